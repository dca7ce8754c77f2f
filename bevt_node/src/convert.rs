//! Conversions between ROS messages and core types, shared by the node and the tool: camera
//! images to [`Frame`]s (zero-copy for rgb8/bgr8/rgba8/bgra8/mono8; YUV 4:2:2 and JPEG/PNG
//! decoded into a reusable buffer), tracker outputs to `vision_msgs/Detection2DArray`.
//!
//! Untrusted sizes are checked before anything is allocated from them: a frame's width,
//! height and pixel count are checked against [`ImageLimits`] from the message fields (raw
//! images) or from the compressed header, read without decoding; the decoder then runs
//! with explicit [`image::Limits`]. A compressed image must also be complete (a JPEG ends
//! with its EOI marker, a PNG with its IEND chunk): the JPEG decoder fills a truncated
//! image with grey instead of failing, and such a frame must not be learned.

use bevt_core::image::MAX_FRAME_SIDE;
use bevt_core::{BBox, Frame, PixelFormat, TrackOutput, TrackState};
use bevt_msgs::geometry_msgs::PoseWithCovariance;
use bevt_msgs::sensor_msgs::{CompressedImage, CompressedImageView, Image, ImageView};
use bevt_msgs::std_msgs::Header;
use bevt_msgs::vision_msgs::{
    BoundingBox2D, Detection2D, Detection2DArray, ObjectHypothesis, ObjectHypothesisWithPose,
    Point2D, Pose2D,
};
use thiserror::Error;

/// Most bytes per pixel a decoder may produce before conversion to RGB8 (16-bit RGBA).
pub const MAX_DECODED_BYTES_PER_PIXEL: u64 = 8;
/// Bytes per pixel of the RGB8 conversion buffer (YUV and compressed input).
pub const RGB_BYTES_PER_PIXEL: u64 = 3;
/// Most bytes per pixel of a frame the node keeps (rgba8/bgra8).
pub const MAX_FRAME_BYTES_PER_PIXEL: u64 = 4;
/// Memory the decoder may use to parse a compressed header (ICC profiles, text chunks).
const HEADER_ALLOC_BYTES: u64 = 4 << 20;
/// Characters of a peer-supplied string (encoding, format, frame_id) echoed in reasons,
/// diagnostics and logs; longer strings are cut and end with `…`.
pub const MAX_ECHO_CHARS: usize = 64;
/// Trailing zero bytes tolerated after a JPEG's EOI marker (some cameras pad buffers).
const JPEG_MAX_TRAILING_ZEROS: usize = 4096;
/// JPEG end-of-image marker.
const JPEG_EOI: [u8; 2] = [0xFF, 0xD9];
/// A PNG's final chunk: length 0, type `IEND`, CRC.
const PNG_IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xAE, 0x42, 0x60, 0x82];

/// A peer-supplied string as echoed in reasons and logs: at most [`MAX_ECHO_CHARS`]
/// characters, then `…`.
pub fn clip(s: &str) -> String {
    match s.char_indices().nth(MAX_ECHO_CHARS) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s.to_string(),
    }
}

/// Largest camera frame the node accepts. Checked before any pixel is decoded or copied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageLimits {
    /// Largest width, pixels.
    pub max_width: u32,
    /// Largest height, pixels.
    pub max_height: u32,
    /// Largest width × height, pixels.
    pub max_pixels: u64,
}

impl Default for ImageLimits {
    /// 4096 × 4096 and 16 MP: above any drone camera's stream.
    fn default() -> Self {
        Self {
            max_width: 4096,
            max_height: 4096,
            max_pixels: 16 << 20,
        }
    }
}

impl ImageLimits {
    /// Checks a frame's size.
    ///
    /// # Errors
    /// [`ConvertError::Malformed`] for an empty frame, [`ConvertError::TooLarge`] for one
    /// over a limit.
    pub fn check(&self, width: u32, height: u32) -> Result<(usize, usize), ConvertError> {
        if width == 0 || height == 0 {
            return Err(ConvertError::Malformed(format!(
                "empty image {width}x{height}"
            )));
        }
        let pixels = width as u64 * height as u64;
        let over = if width > self.max_width {
            Some(format!(
                "width {width} > max_image_width {}",
                self.max_width
            ))
        } else if height > self.max_height {
            Some(format!(
                "height {height} > max_image_height {}",
                self.max_height
            ))
        } else if pixels > self.max_pixels {
            Some(format!(
                "{pixels} pixels > max_image_pixels {}",
                self.max_pixels
            ))
        } else if width as usize > MAX_FRAME_SIDE || height as usize > MAX_FRAME_SIDE {
            Some(format!("a side exceeds the maximum {MAX_FRAME_SIDE}"))
        } else {
            None
        };
        match over {
            Some(reason) => Err(ConvertError::TooLarge {
                width,
                height,
                reason,
            }),
            None => Ok((width as usize, height as usize)),
        }
    }

    /// Bytes the decoder may allocate for one frame of these limits.
    pub fn decode_bytes(&self) -> u64 {
        self.max_pixels.saturating_mul(MAX_DECODED_BYTES_PER_PIXEL)
    }
}

/// Why an image message cannot be used.
#[derive(Debug, Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum ConvertError {
    /// The encoding is not one the node reads.
    #[error("unsupported image encoding {0:?} (supported: rgb8, bgr8, rgba8, bgra8, mono8, yuv422, yuv422_yuy2, and compressed jpeg/png)")]
    UnsupportedEncoding(String),
    /// Width, height, step and data length disagree, or a size is absurd.
    #[error("malformed image: {0}")]
    Malformed(String),
    /// The frame is larger than the node's limits; nothing was decoded or kept.
    #[error("image {width}x{height} rejected: {reason}")]
    TooLarge {
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// Which limit it exceeds.
        reason: String,
    },
    /// A compressed image could not be decoded.
    #[error("cannot decode {format} image: {reason}")]
    Decode {
        /// The message's format field.
        format: String,
        /// Decoder message.
        reason: String,
    },
}

/// Reusable buffer for decoded / converted pixels.
#[derive(Debug, Default)]
pub struct PixelBuffer {
    rgb: Vec<u8>,
}

impl PixelBuffer {
    /// Bytes held (capacity), for memory accounting.
    pub fn capacity(&self) -> usize {
        self.rgb.capacity()
    }

    /// Sets the buffer to `len` bytes, giving memory back when it holds much more than
    /// that (after a larger frame).
    fn reset_to(&mut self, len: usize) {
        if self.rgb.capacity() > len.saturating_mul(2) {
            self.rgb = Vec::new();
        }
        self.rgb.clear();
        self.rgb.resize(len, 0);
    }
}

/// YUV 4:2:2 byte order: offsets of (Y0, U, Y1, V) in each 4-byte pair of pixels.
fn yuv422_order(encoding: &str) -> Option<[usize; 4]> {
    match encoding {
        // ROS `yuv422` is UYVY.
        "yuv422" | "uyvy" => Some([1, 0, 3, 2]),
        // `yuv422_yuy2` is YUYV.
        "yuv422_yuy2" | "yuyv" => Some([0, 1, 2, 3]),
        _ => None,
    }
}

fn yuv_to_rgb(y: f32, u: f32, v: f32) -> [u8; 3] {
    // ITU-R BT.601, studio swing.
    let c = 1.164 * (y - 16.0);
    let (d, e) = (u - 128.0, v - 128.0);
    let clamp = |x: f32| x.round().clamp(0.0, 255.0) as u8;
    [
        clamp(c + 1.596 * e),
        clamp(c - 0.392 * d - 0.813 * e),
        clamp(c + 2.017 * d),
    ]
}

/// A [`Frame`] view of a `sensor_msgs/Image`, converting into `buf` when the encoding is
/// not directly usable.
///
/// # Errors
/// [`ConvertError`] for unsupported encodings, sizes that disagree with the data, and
/// frames over `limits`.
pub fn frame_from_image<'a>(
    msg: &'a Image,
    buf: &'a mut PixelBuffer,
    limits: &ImageLimits,
) -> Result<Frame<'a>, ConvertError> {
    frame_from_image_view(&msg.view(), buf, limits)
}

/// [`frame_from_image`] of a borrowed message (e.g. deserialised in place from a bag):
/// the pixels are used where they lie when the encoding allows.
///
/// # Errors
/// As [`frame_from_image`].
pub fn frame_from_image_view<'a>(
    msg: &ImageView<'a>,
    buf: &'a mut PixelBuffer,
    limits: &ImageLimits,
) -> Result<Frame<'a>, ConvertError> {
    let (w, h) = limits.check(msg.width, msg.height)?;
    let enc = msg.encoding.to_ascii_lowercase();
    let step = msg.step as usize;
    let expect = step
        .checked_mul(h)
        .ok_or_else(|| ConvertError::Malformed("step × height overflows".into()))?;
    if msg.data.len() != expect {
        return Err(ConvertError::Malformed(format!(
            "data has {} bytes, step {step} × height {h} = {expect}",
            msg.data.len()
        )));
    }
    let direct = match enc.as_str() {
        "rgb8" => Some(PixelFormat::Rgb8),
        "bgr8" => Some(PixelFormat::Bgr8),
        "rgba8" => Some(PixelFormat::Rgba8),
        "bgra8" => Some(PixelFormat::Bgra8),
        "mono8" | "8uc1" => Some(PixelFormat::Mono8),
        _ => None,
    };
    if let Some(fmt) = direct {
        return Frame::new(msg.data, w, h, step, fmt)
            .map_err(|e| ConvertError::Malformed(e.to_string()));
    }
    let Some(order) = yuv422_order(&enc) else {
        return Err(ConvertError::UnsupportedEncoding(clip(&msg.encoding)));
    };
    if w % 2 != 0 || step < 2 * w {
        return Err(ConvertError::Malformed(format!(
            "{} needs an even width and step ≥ 2×width, got width {w}, step {step}",
            clip(&msg.encoding)
        )));
    }
    buf.reset_to(w * h * 3);
    for r in 0..h {
        let src = &msg.data[r * step..r * step + 2 * w];
        let dst = &mut buf.rgb[r * w * 3..(r + 1) * w * 3];
        for (pair, out) in src.chunks_exact(4).zip(dst.chunks_exact_mut(6)) {
            let (y0, u, y1, v) = (
                pair[order[0]] as f32,
                pair[order[1]] as f32,
                pair[order[2]] as f32,
                pair[order[3]] as f32,
            );
            out[..3].copy_from_slice(&yuv_to_rgb(y0, u, v));
            out[3..].copy_from_slice(&yuv_to_rgb(y1, u, v));
        }
    }
    Frame::packed(&buf.rgb, w, h, PixelFormat::Rgb8)
        .map_err(|e| ConvertError::Malformed(e.to_string()))
}

/// True when `data` is a whole JPEG or PNG stream: it ends with the JPEG EOI marker
/// (trailing zero padding allowed) or the PNG IEND chunk.
fn is_complete(kind: image::ImageFormat, data: &[u8]) -> bool {
    match kind {
        image::ImageFormat::Png => data.ends_with(&PNG_IEND),
        _ => {
            let zeros = data.iter().rev().take_while(|&&b| b == 0).count();
            zeros <= JPEG_MAX_TRAILING_ZEROS && data[..data.len() - zeros].ends_with(&JPEG_EOI)
        }
    }
}

/// A [`Frame`] of a decoded `sensor_msgs/CompressedImage` (JPEG or PNG).
///
/// The size is read from the header and checked against `limits` before anything is
/// decoded; the decoder then runs with explicit [`image::Limits`] (dimensions and
/// [`ImageLimits::decode_bytes`]), and the stream must be complete.
///
/// # Errors
/// [`ConvertError`] for other formats, corrupt or truncated data, or images over `limits`.
pub fn frame_from_compressed<'a>(
    msg: &CompressedImage,
    buf: &'a mut PixelBuffer,
    limits: &ImageLimits,
) -> Result<Frame<'a>, ConvertError> {
    frame_from_compressed_view(&msg.view(), buf, limits)
}

/// [`frame_from_compressed`] of a borrowed message (e.g. deserialised in place from a bag).
///
/// # Errors
/// As [`frame_from_compressed`].
pub fn frame_from_compressed_view<'a>(
    msg: &CompressedImageView<'_>,
    buf: &'a mut PixelBuffer,
    limits: &ImageLimits,
) -> Result<Frame<'a>, ConvertError> {
    let fmt = msg.format.to_ascii_lowercase();
    let kind = if fmt.contains("jpeg") || fmt.contains("jpg") {
        image::ImageFormat::Jpeg
    } else if fmt.contains("png") {
        image::ImageFormat::Png
    } else {
        return Err(ConvertError::UnsupportedEncoding(clip(&msg.format)));
    };
    let err = |e: &dyn std::fmt::Display| ConvertError::Decode {
        format: clip(&msg.format),
        reason: clip(&e.to_string()),
    };
    // 1. The header alone: dimensions, with only a small allocation allowed.
    let mut header_limits = image::Limits::default();
    header_limits.max_alloc = Some(HEADER_ALLOC_BYTES);
    let mut reader = image::ImageReader::with_format(std::io::Cursor::new(msg.data), kind);
    reader.limits(header_limits);
    let (width, height) = reader.into_dimensions().map_err(|e| err(&e))?;
    let (w, h) = limits.check(width, height)?;
    // 2. A truncated stream is an error, not a partly grey frame.
    if !is_complete(kind, msg.data) {
        return Err(ConvertError::Decode {
            format: clip(&msg.format),
            reason: format!(
                "truncated data ({} bytes): no {} at the end",
                msg.data.len(),
                if kind == image::ImageFormat::Png {
                    "IEND chunk"
                } else {
                    "EOI marker"
                }
            ),
        });
    }
    // 3. Decode under explicit limits.
    let mut decode_limits = image::Limits::default();
    decode_limits.max_image_width = Some(limits.max_width);
    decode_limits.max_image_height = Some(limits.max_height);
    decode_limits.max_alloc = Some(limits.decode_bytes());
    let mut reader = image::ImageReader::with_format(std::io::Cursor::new(msg.data), kind);
    reader.limits(decode_limits);
    let img = reader.decode().map_err(|e| err(&e))?;
    if (img.width(), img.height()) != (width, height) {
        return Err(err(&"decoded size differs from the header"));
    }
    buf.reset_to(0);
    buf.rgb = img.into_rgb8().into_raw();
    Frame::packed(&buf.rgb, w, h, PixelFormat::Rgb8)
        .map_err(|e| ConvertError::Malformed(e.to_string()))
}

/// `vision_msgs/BoundingBox2D` of box `b`: its centre, no rotation, its size (inverse of
/// the box part of [`bbox_from_detection`]).
pub fn bbox_2d(b: BBox) -> BoundingBox2D {
    let c = b.center();
    BoundingBox2D {
        center: Pose2D {
            position: Point2D {
                x: c.x as f64,
                y: c.y as f64,
            },
            theta: 0.0,
        },
        size_x: b.w as f64,
        size_y: b.h as f64,
    }
}

/// `vision_msgs/Detection2DArray` for one tracker output: the box (centre, size), the
/// confidence as the hypothesis score, the track id as `id`; no detection while the target
/// is lost (the ROS convention: no detection rather than a wrong one).
pub fn detections_from_output(
    header: &Header,
    out: Option<&TrackOutput>,
    track_id: u32,
    class_id: &str,
) -> Detection2DArray {
    let detections = out
        .filter(|o| o.state != TrackState::Lost)
        .map(|o| {
            vec![Detection2D {
                header: header.clone(),
                results: vec![ObjectHypothesisWithPose {
                    hypothesis: ObjectHypothesis {
                        class_id: class_id.to_string(),
                        score: o.confidence as f64,
                    },
                    pose: PoseWithCovariance::default(),
                }],
                bbox: bbox_2d(o.bbox),
                id: track_id.to_string(),
            }]
        })
        .unwrap_or_default();
    Detection2DArray {
        header: header.clone(),
        detections,
    }
}

/// A `bevt_msgs/Reinit` request for box `b` drawn on the frame stamped `stamp`.
pub fn reinit_request(
    b: BBox,
    stamp: bevt_msgs::builtin_interfaces::Time,
    frame_id: &str,
) -> bevt_msgs::bevt::ReinitRequest {
    bevt_msgs::bevt::ReinitRequest {
        x: b.x as f64,
        y: b.y as f64,
        width: b.w as f64,
        height: b.h as f64,
        stamp,
        frame_id: frame_id.to_string(),
    }
}

/// The box of a detection (inverse of [`detections_from_output`]).
pub fn bbox_from_detection(d: &Detection2D) -> BBox {
    let b = &d.bbox;
    BBox::new(
        (b.center.position.x - b.size_x / 2.0) as f32,
        (b.center.position.y - b.size_y / 2.0) as f32,
        b.size_x as f32,
        b.size_y as f32,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    const L: ImageLimits = ImageLimits {
        max_width: 4096,
        max_height: 4096,
        max_pixels: 16 << 20,
    };

    fn img(enc: &str, w: u32, h: u32, step: u32, data: Vec<u8>) -> Image {
        Image {
            encoding: enc.into(),
            width: w,
            height: h,
            step,
            data,
            ..Image::default()
        }
    }

    #[test]
    fn direct_encodings_are_zero_copy_views() {
        let m = img("bgr8", 2, 2, 8, vec![1; 16]);
        let mut b = PixelBuffer::default();
        let f = frame_from_image(&m, &mut b, &L).unwrap();
        assert_eq!(
            (f.width(), f.height(), f.stride(), f.format()),
            (2, 2, 8, PixelFormat::Bgr8)
        );
        assert!(std::ptr::eq(f.data().as_ptr(), m.data.as_ptr()));
    }

    #[test]
    fn size_mismatches_and_absurd_sizes_are_rejected() {
        let mut b = PixelBuffer::default();
        for m in [
            img("rgb8", 2, 2, 6, vec![0; 11]),
            img("rgb8", 2, 2, 5, vec![0; 10]),
            img("rgb8", 0, 2, 6, vec![]),
            img("mono8", 100_000, 1, 100_000, vec![0; 100_000]),
            img("rgb8", u32::MAX, u32::MAX, u32::MAX, vec![0; 4]),
        ] {
            assert!(
                matches!(
                    frame_from_image(&m, &mut b, &L),
                    Err(ConvertError::Malformed(_) | ConvertError::TooLarge { .. })
                ),
                "{m:?}"
            );
        }
    }

    #[test]
    fn unsupported_encodings_are_named() {
        let mut b = PixelBuffer::default();
        let e = frame_from_image(&img("16UC1", 1, 1, 2, vec![0; 2]), &mut b, &L).unwrap_err();
        assert!(e.to_string().contains("16UC1"), "{e}");
    }

    #[test]
    fn yuv422_variants_decode_grey_and_colour() {
        let mut b = PixelBuffer::default();
        // UYVY: mid grey (Y=126, U=V=128) → about 128 on every channel.
        let m = img("yuv422", 2, 1, 4, vec![128, 126, 128, 126]);
        let f = frame_from_image(&m, &mut b, &L).unwrap();
        assert!(
            f.data()[..6].iter().all(|&v| (v as i32 - 128).abs() <= 1),
            "{:?}",
            &f.data()[..6]
        );
        // YUYV: saturated red (Y=81, U=90, V=240).
        let m = img("yuv422_yuy2", 2, 1, 4, vec![81, 90, 81, 240]);
        let f = frame_from_image(&m, &mut b, &L).unwrap();
        let px = &f.data()[..3];
        assert!(px[0] > 240 && px[1] < 15 && px[2] < 15, "{px:?}");
        assert!(frame_from_image(&img("yuv422", 3, 1, 6, vec![0; 6]), &mut b, &L).is_err());
    }

    #[test]
    fn compressed_png_and_jpeg_decode_and_corrupt_data_is_an_error() {
        let mut png = Vec::new();
        image::RgbImage::from_pixel(4, 3, image::Rgb([10, 20, 30]))
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let mut b = PixelBuffer::default();
        let m = CompressedImage {
            format: "png".into(),
            data: png,
            ..Default::default()
        };
        let f = frame_from_compressed(&m, &mut b, &L).unwrap();
        assert_eq!((f.width(), f.height()), (4, 3));
        assert_eq!(&f.data()[..3], &[10, 20, 30]);
        let bad = CompressedImage {
            format: "rgb8; jpeg compressed bgr8".into(),
            data: vec![0xFF, 0xD8, 0x00, 0x01],
            ..Default::default()
        };
        assert!(matches!(
            frame_from_compressed(&bad, &mut b, &L),
            Err(ConvertError::Decode { .. })
        ));
        let tiff = CompressedImage {
            format: "tiff".into(),
            ..Default::default()
        };
        assert!(matches!(
            frame_from_compressed(&tiff, &mut b, &L),
            Err(ConvertError::UnsupportedEncoding(_))
        ));
    }

    fn encode(img: &image::DynamicImage, fmt: image::ImageFormat) -> Vec<u8> {
        let mut out = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut out), fmt)
            .unwrap();
        out
    }

    fn textured(w: u32, h: u32) -> image::DynamicImage {
        image::DynamicImage::ImageRgb8(image::RgbImage::from_fn(w, h, |x, y| {
            image::Rgb([(x * 7 + y * 3) as u8, (x * y) as u8, (x ^ y) as u8])
        }))
    }

    fn compressed(format: &str, data: Vec<u8>) -> CompressedImage {
        CompressedImage {
            format: format.into(),
            data,
            ..Default::default()
        }
    }

    /// CRC-32 (IEEE) of PNG chunks.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = 0xFFFF_FFFFu32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    (c >> 1) ^ 0xEDB8_8320
                } else {
                    c >> 1
                };
            }
        }
        !c
    }

    /// A small valid PNG whose IHDR declares `w`×`h` (CRC fixed): a decompression bomb's
    /// header.
    fn png_declaring(w: u32, h: u32) -> Vec<u8> {
        let mut png = encode(
            &image::DynamicImage::ImageLuma8(image::GrayImage::new(8, 8)),
            image::ImageFormat::Png,
        );
        png[16..20].copy_from_slice(&w.to_be_bytes());
        png[20..24].copy_from_slice(&h.to_be_bytes());
        let crc = crc32(&png[12..29]);
        png[29..33].copy_from_slice(&crc.to_be_bytes());
        png
    }

    /// A small valid JPEG whose SOF0 declares `w`×`h`.
    fn jpeg_declaring(w: u16, h: u16) -> Vec<u8> {
        let mut jpg = encode(&textured(16, 16), image::ImageFormat::Jpeg);
        let sof = jpg
            .windows(2)
            .position(|p| p == [0xFF, 0xC0])
            .expect("baseline SOF0");
        jpg[sof + 5..sof + 7].copy_from_slice(&h.to_be_bytes());
        jpg[sof + 7..sof + 9].copy_from_slice(&w.to_be_bytes());
        jpg
    }

    #[test]
    fn image_bombs_are_rejected_from_the_header_without_decoding() {
        let mut b = PixelBuffer::default();
        let jpg = jpeg_declaring(16000, 16000);
        assert!(jpg.len() < 1000, "{} bytes", jpg.len());
        let png = png_declaring(16000, 16000);
        for (m, name) in [
            (compressed("jpeg", jpg), "jpeg"),
            (compressed("png", png), "png"),
        ] {
            match frame_from_compressed(&m, &mut b, &L) {
                Err(ConvertError::TooLarge {
                    width,
                    height,
                    reason,
                }) => {
                    assert_eq!((width, height), (16000, 16000), "{name}");
                    assert!(reason.contains("max_image_width"), "{name}: {reason}");
                }
                other => panic!("{name}: {other:?}"),
            }
            assert_eq!(b.capacity(), 0, "{name}: nothing was decoded");
        }
        // Each limit is applied and named.
        let small = ImageLimits {
            max_width: 100,
            max_height: 50,
            max_pixels: 3000,
        };
        for (w, h, why) in [
            (101, 10, "max_image_width"),
            (10, 51, "max_image_height"),
            (100, 31, "max_image_pixels"),
        ] {
            let m = compressed("png", png_declaring(w, h));
            let e = frame_from_compressed(&m, &mut b, &small).unwrap_err();
            assert!(e.to_string().contains(why), "{w}x{h}: {e}");
            let raw = img("mono8", w, h, w, vec![0; (w * h) as usize]);
            let e = frame_from_image(&raw, &mut b, &small).unwrap_err();
            assert!(e.to_string().contains(why), "raw {w}x{h}: {e}");
        }
        let ok = compressed("png", encode(&textured(100, 30), image::ImageFormat::Png));
        assert!(frame_from_compressed(&ok, &mut b, &small).is_ok());
    }

    #[test]
    fn truncated_jpeg_and_png_are_errors() {
        let mut b = PixelBuffer::default();
        let img = textured(320, 240);
        let jpg = encode(&img, image::ImageFormat::Jpeg);
        let png = encode(&img, image::ImageFormat::Png);
        // Whole streams decode; zero padding after the JPEG's EOI is tolerated.
        let mut padded = jpg.clone();
        padded.extend([0; 16]);
        for m in [
            compressed("jpeg", jpg.clone()),
            compressed("jpeg", padded),
            compressed("png", png.clone()),
        ] {
            let f = frame_from_compressed(&m, &mut b, &L).unwrap();
            assert_eq!((f.width(), f.height()), (320, 240));
        }
        for (m, what) in [
            (compressed("jpeg", jpg[..jpg.len() / 2].to_vec()), "EOI"),
            (compressed("jpeg", jpg[..jpg.len() - 2].to_vec()), "EOI"),
            (compressed("png", png[..png.len() / 2].to_vec()), ""),
            (compressed("png", png[..png.len() - 12].to_vec()), "IEND"),
        ] {
            let e = frame_from_compressed(&m, &mut b, &L).unwrap_err();
            assert!(matches!(e, ConvertError::Decode { .. }), "{e}");
            assert!(e.to_string().contains(what), "{e}");
        }
    }

    #[test]
    fn grey_png_is_expanded_within_the_limits_and_the_buffer_shrinks() {
        let mut b = PixelBuffer::default();
        let grey = image::DynamicImage::ImageLuma8(image::GrayImage::from_pixel(
            640,
            480,
            image::Luma([77]),
        ));
        let m = compressed("png", encode(&grey, image::ImageFormat::Png));
        let f = frame_from_compressed(&m, &mut b, &L).unwrap();
        assert_eq!(&f.data()[..3], &[77, 77, 77]);
        assert!(b.capacity() >= 640 * 480 * 3);
        // A much smaller YUV frame afterwards: the buffer gives the memory back.
        let y = img("yuv422", 2, 1, 4, vec![128, 126, 128, 126]);
        frame_from_image(&y, &mut b, &L).unwrap();
        assert!(b.capacity() < 1024, "{}", b.capacity());
    }

    #[test]
    fn long_peer_strings_are_clipped_in_reasons() {
        let mut b = PixelBuffer::default();
        let long = "x".repeat(10_000);
        let e = frame_from_image(&img(&long, 1, 1, 1, vec![0]), &mut b, &L).unwrap_err();
        let s = e.to_string();
        assert!(s.len() < 400, "{} chars", s.len());
        assert!(
            s.contains(&format!("{}…", "x".repeat(MAX_ECHO_CHARS))),
            "{s}"
        );
        let e = frame_from_compressed(&compressed(&long, vec![]), &mut b, &L).unwrap_err();
        assert!(e.to_string().len() < 400);
        assert_eq!(clip("short"), "short");
        assert_eq!(clip(&"é".repeat(100)).chars().count(), MAX_ECHO_CHARS + 1);
    }

    #[test]
    fn detection_round_trips_the_box_and_carries_the_score() {
        let out = TrackOutput {
            bbox: BBox::new(10.0, 20.0, 30.0, 40.0),
            consensus: 0.5,
            learned: true,
            peak: 0.1,
            scale: 1.0,
            confidence: 0.9,
            state: bevt_core::TrackState::Tracking,
            reason: bevt_core::StateReason::Confident,
        };
        let d = detections_from_output(&Header::default(), Some(&out), 3, "target");
        assert_eq!(d.detections.len(), 1);
        assert_eq!(bbox_from_detection(&d.detections[0]), out.bbox);
        let b = &d.detections[0].bbox;
        assert_eq!((b.center.position.x, b.center.position.y), (25.0, 40.0));
        assert_eq!((b.size_x, b.size_y, b.center.theta), (30.0, 40.0, 0.0));
        assert!((d.detections[0].results[0].hypothesis.score - 0.9).abs() < 1e-6);
        assert_eq!(d.detections[0].id, "3");
        assert!(detections_from_output(&Header::default(), None, 3, "t")
            .detections
            .is_empty());
        let lost = TrackOutput {
            state: bevt_core::TrackState::Lost,
            confidence: 0.1,
            ..out
        };
        let d = detections_from_output(&Header::default(), Some(&lost), 3, "t");
        assert!(d.detections.is_empty());
        for state in [
            bevt_core::TrackState::Uncertain,
            bevt_core::TrackState::Reacquired,
        ] {
            let o = TrackOutput { state, ..out };
            let d = detections_from_output(&Header::default(), Some(&o), 3, "t");
            assert_eq!(d.detections.len(), 1);
        }
    }
}
