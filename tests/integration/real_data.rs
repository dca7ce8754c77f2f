//! Accuracy regression on a real UAV123@10fps dev sequence (needs `../shared`; skipped with
//! a printed reason otherwise).

use bevt_core::{BevtTracker, TrackerConfig};
use bevt_node::tool::dataset::open_dataset;
use bevt_node::tool::report::summarize_run;
use bevt_node::tool::runner::run_sequence;
use bevt_tests::dev_dataset;

/// Measured with the default configuration (README): building4 P@20 1.000, AUC 0.643 (0.729
/// with the filter's box, `box_refine.mode: none`: building4 is the sequence the learned box
/// loses, its head drawing the rooftop with its surroundings; docs/results.md). Floors leave
/// room for float differences across machines, not for regressions.
const BUILDING4_MIN_P20: f64 = 0.95;
const BUILDING4_MIN_AUC: f64 = 0.62;

#[test]
fn building4_accuracy_does_not_regress() {
    let Some(root) = dev_dataset() else {
        bevt_tests::skip(
            "building4_accuracy_does_not_regress",
            "../shared/datasets/uav123_10fps_dev is absent",
        );
        return;
    };
    let mut ds = open_dataset(&root).unwrap();
    ds.select(&["building4".to_string()]).unwrap();
    let mut t = BevtTracker::new(TrackerConfig::default().validate().unwrap());
    let run = run_sequence(&ds.sequences[0], &mut t, |_, _| {});
    assert!(run.run.error.is_none(), "{:?}", run.run.error);
    let s = summarize_run(&run);
    println!(
        "building4: P@20 {:.3} AUC {:.3} fps {:.1}",
        s.precision_20, s.auc, s.fps
    );
    assert_eq!(s.frames_tracked, 263);
    assert!(
        s.precision_20 >= BUILDING4_MIN_P20,
        "P@20 {}",
        s.precision_20
    );
    assert!(s.auc >= BUILDING4_MIN_AUC, "AUC {}", s.auc);
}
