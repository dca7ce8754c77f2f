#!/usr/bin/env python3
"""Rule 3 of the selection protocol (docs/results.md#selection-protocol), read above the
rounding floor.

Reads the runs of scripts/protocol-runs.sh (target/protocol/LABEL/CONDITION/summary.json) of
the incumbent, of its null variants (the incumbent's build with one-line changes that only
move last bits: scripts/rounding-floor/) and of each challenger, and prints the mean AUC over
the dev set's sequences per condition, the null band (lowest and highest of the incumbent and
its null variants), and for each challenger the verdict:

- refused when, under any of the ten perturbations, its AUC is more than PER (0.02) below the
  null band's lowest value, or when its mean over the ten perturbations is more than POOLED
  (0.0) below the lowest mean of the ten among the null band's builds;
- the plain rule 3 of before (loss against the incumbent alone over 0.02) is printed beside it;
- and where its unperturbed P@20 / AUC lie against the band: inside it, a challenger made for
  cost is equal to the incumbent (rule 2's cost trade).

A run that holds fewer sequences than another (still running, or cut short: summary.json is
rewritten as each sequence finishes) is an error, not a mean over fewer sequences.

Usage: scripts/rule3.py --incumbent LABEL [--null LABEL ...] [--per 0.02] [--pooled 0.0]
                        [--root target/protocol] CHALLENGER_LABEL ...
Standard library only.
"""
import argparse
import json
import os
import sys

CONDITIONS = [
    ("none", "none"),
    ("shake16s1", "shake 16 s1"),
    ("shake16s2", "shake 16 s2"),
    ("shake8s2", "shake 8 s2"),
    ("tiny_shake", "tiny + shake"),
    ("tiny", "tiny"),
    ("zoom", "zoom"),
    ("aspect", "aspect"),
    ("light", "light"),
    ("lookalike", "look-alike"),
    ("blur", "blur"),
]
PERTURBED = [c for c, _ in CONDITIONS if c != "none"]


def load(root, label):
    """condition -> (mean AUC, mean P@20, {sequence: AUC}) of one build's runs."""
    runs = {}
    for cond, _ in CONDITIONS:
        path = os.path.join(root, label, cond, "summary.json")
        try:
            with open(path) as f:
                s = json.load(f)
        except (OSError, ValueError) as e:
            sys.exit(f"rule3: {path}: {e} (run scripts/protocol-runs.sh {label} first)")
        seqs = s["sequences"]
        bad = [q["name"] for q in seqs if q.get("status") != "ok"]
        if bad:
            sys.exit(f"rule3: {path}: sequence(s) {bad} did not finish")
        o = s["overall"]
        runs[cond] = (o["auc"], o["precision_20"], {q["name"]: q["auc"] for q in seqs})
    return runs


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--incumbent", required=True)
    ap.add_argument("--null", action="append", default=[])
    ap.add_argument("--per", type=float, default=0.02)
    ap.add_argument("--pooled", type=float, default=0.0)
    ap.add_argument("--root", default="target/protocol")
    ap.add_argument("challengers", nargs="*")
    a = ap.parse_args()

    band_labels = [a.incumbent] + a.null
    builds = {lab: load(a.root, lab) for lab in band_labels + a.challengers}
    inc = builds[a.incumbent]
    # summary.json is rewritten as each sequence finishes: a run still going (or cut short)
    # holds fewer sequences than the others, and its mean is of another set. Every run must
    # hold every sequence any run holds.
    everyone = set().union(*(r[2] for runs in builds.values() for r in runs.values()))
    for lab, runs in builds.items():
        for cond, r in runs.items():
            missing = sorted(everyone - set(r[2]))
            if missing:
                sys.exit(
                    f"rule3: {os.path.join(a.root, lab, cond, 'summary.json')}: "
                    f"{len(r[2])} of {len(everyone)} sequences, missing {missing} "
                    "(still running or cut short)"
                )

    def mean10(runs):
        return sum(runs[c][0] for c in PERTURBED) / len(PERTURBED)

    floor = {c: min(builds[lab][c][0] for lab in band_labels) for c, _ in CONDITIONS}
    top = {c: max(builds[lab][c][0] for lab in band_labels) for c, _ in CONDITIONS}
    floor10 = min(mean10(builds[lab]) for lab in band_labels)
    top10 = max(mean10(builds[lab]) for lab in band_labels)

    head = ["condition"] + band_labels + ["null band"] + a.challengers
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for c, name in CONDITIONS:
        row = [name] + [f"{builds[lab][c][0]:.3f}" for lab in band_labels]
        row.append(f"{floor[c]:.3f}–{top[c]:.3f}")
        row += [f"{builds[lab][c][0]:.3f}" for lab in a.challengers]
        print("| " + " | ".join(row) + " |")
    row = ["mean of the ten"] + [f"{mean10(builds[lab]):.3f}" for lab in band_labels]
    row.append(f"{floor10:.3f}–{top10:.3f}")
    row += [f"{mean10(builds[lab]):.3f}" for lab in a.challengers]
    print("| " + " | ".join(row) + " |")
    p_floor = min(builds[lab]["none"][1] for lab in band_labels)
    p_top = max(builds[lab]["none"][1] for lab in band_labels)
    row = ["P@20, none"] + [f"{builds[lab]['none'][1]:.3f}" for lab in band_labels]
    row.append(f"{p_floor:.3f}–{p_top:.3f}")
    row += [f"{builds[lab]['none'][1]:.3f}" for lab in a.challengers]
    print("| " + " | ".join(row) + " |")
    print()

    refused_any = False
    for lab in a.challengers:
        runs = builds[lab]
        beyond = [
            f"{c} {runs[c][0]:.3f} < floor {floor[c]:.3f} - {a.per}"
            for c in PERTURBED
            if runs[c][0] < floor[c] - a.per - 1e-12
        ]
        pooled_loss = mean10(runs) < floor10 - a.pooled - 1e-12
        plain = [
            f"{c} {runs[c][0] - inc[c][0]:+.3f}"
            for c in PERTURBED
            if runs[c][0] < inc[c][0] - a.per - 1e-12
        ]
        reasons = beyond + ([f"mean of ten {mean10(runs):.3f} < {floor10:.3f} - {a.pooled}"] if pooled_loss else [])
        verdict = "REFUSED: " + "; ".join(reasons) if reasons else "passes"
        refused_any |= bool(reasons)
        print(f"{lab}: rule 3 above the rounding floor {verdict}")
        print(f"{lab}: plain rule 3 (against {a.incumbent} alone): " + ("refused: " + ", ".join(plain) if plain else "passes"))
        auc, p20 = runs["none"][0], runs["none"][1]
        if auc > top["none"] + 1e-12:
            where = "above the band (a gain rule 2 can read)"
        elif auc < floor["none"] - 1e-12 or p20 < p_floor - 1e-12:
            where = "below the band (a loss)"
        else:
            where = "within the band (equal to the incumbent: rule 2 takes the cheaper)"
        print(f"{lab}: dev set unperturbed {p20:.3f} / {auc:.3f}: {where}")
    return 1 if refused_any else 0


if __name__ == "__main__":
    sys.exit(main())
