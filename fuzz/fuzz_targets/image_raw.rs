//! libFuzzer target `image_raw`: the body is `bevt_tests::fuzz::image_raw`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| bevt_tests::fuzz::image_raw(data));
