//! libFuzzer target `annotation`: the body is `bevt_tests::fuzz::annotation`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::annotation(data));
