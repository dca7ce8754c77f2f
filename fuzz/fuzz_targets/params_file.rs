//! libFuzzer target `params_file`: the body is `bevt_tests::fuzz::params_file`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::params_file(data));
