//! libFuzzer target `node_requests`: the body is `bevt_tests::fuzz::node_requests`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::node_requests(data));
