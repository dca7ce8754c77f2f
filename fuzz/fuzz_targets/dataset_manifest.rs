//! libFuzzer target `dataset_manifest`: the body is `bevt_tests::fuzz::dataset_manifest`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::dataset_manifest(data));
