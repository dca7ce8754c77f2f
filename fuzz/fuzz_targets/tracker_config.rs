//! libFuzzer target `tracker_config`: the body is `bevt_tests::fuzz::tracker_config`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::tracker_config(data));
