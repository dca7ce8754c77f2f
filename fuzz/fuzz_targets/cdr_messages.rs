//! libFuzzer target `cdr_messages`: the body is `bevt_tests::fuzz::cdr_messages`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::cdr_messages(data));
