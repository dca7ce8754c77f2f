//! libFuzzer target `param_requests`: the body is `bevt_tests::fuzz::param_requests`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::param_requests(data));
