//! libFuzzer target `bag_reader`: the body is `bevt_tests::fuzz::bag_reader`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::bag_reader(data));
