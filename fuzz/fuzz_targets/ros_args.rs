//! libFuzzer target `ros_args`: the body is `bevt_tests::fuzz::ros_args`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::ros_args(data));
