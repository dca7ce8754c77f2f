//! Every program of the package answers `--help` and `-h` with its usage, on standard output,
//! with exit status 0, and refuses an unknown argument with a non-zero status.

use std::process::Command;

const PROGRAMS: [(&str, &str); 3] = [
    ("bevt", env!("CARGO_BIN_EXE_bevt")),
    ("bevt_node", env!("CARGO_BIN_EXE_bevt_node")),
    ("bevt_latency", env!("CARGO_BIN_EXE_bevt_latency")),
];

#[test]
fn every_program_answers_help() {
    for (name, exe) in PROGRAMS {
        for flag in ["--help", "-h"] {
            let out = Command::new(exe)
                .arg(flag)
                .output()
                .expect("run the program");
            let text = String::from_utf8_lossy(&out.stdout);
            assert!(
                out.status.success(),
                "{name} {flag}: {:?}\n{text}",
                out.status
            );
            assert!(
                text.contains("Usage") && text.contains(name),
                "{name} {flag} printed no usage naming the program:\n{text}"
            );
        }
    }
}

#[test]
fn bevt_node_refuses_an_unknown_argument() {
    let out = Command::new(env!("CARGO_BIN_EXE_bevt_node"))
        .arg("--bogus-flag")
        .output()
        .expect("run bevt_node");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown argument"));
}
