//! libFuzzer target `image_compressed`: the body is `bevt_tests::fuzz::image_compressed`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::image_compressed(data));
