//! Conversions between ROS messages and core types: camera images to [`Frame`]s (zero-copy
//! for rgb8/bgr8/rgba8/bgra8/mono8; YUV 4:2:2 and JPEG/PNG decoded into a reusable
//! buffer), tracker outputs to `vision_msgs/Detection2DArray`.
//!
//! Untrusted sizes are checked before anything is allocated from them.

use bevt_core::image::MAX_FRAME_SIDE;
use bevt_core::{BBox, Frame, PixelFormat, TrackOutput};
use bevt_msgs::geometry_msgs::PoseWithCovariance;
use bevt_msgs::sensor_msgs::{CompressedImage, Image};
use bevt_msgs::std_msgs::Header;
use bevt_msgs::vision_msgs::{
    BoundingBox2D, Detection2D, Detection2DArray, ObjectHypothesis, ObjectHypothesisWithPose,
    Point2D, Pose2D,
};
use thiserror::Error;

/// Largest decoded image accepted from a compressed message, bytes.
pub const MAX_DECODED_BYTES: u64 = 256 << 20;

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

fn check_geometry(width: u32, height: u32) -> Result<(usize, usize), ConvertError> {
    let (w, h) = (width as usize, height as usize);
    if w == 0 || h == 0 {
        return Err(ConvertError::Malformed(format!("empty image {w}x{h}")));
    }
    if w > MAX_FRAME_SIDE || h > MAX_FRAME_SIDE {
        return Err(ConvertError::Malformed(format!(
            "{w}x{h} exceeds the maximum side {MAX_FRAME_SIDE}"
        )));
    }
    Ok((w, h))
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
/// [`ConvertError`] for unsupported encodings and sizes that disagree with the data.
pub fn frame_from_image<'a>(
    msg: &'a Image,
    buf: &'a mut PixelBuffer,
) -> Result<Frame<'a>, ConvertError> {
    let (w, h) = check_geometry(msg.width, msg.height)?;
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
        return Frame::new(&msg.data, w, h, step, fmt)
            .map_err(|e| ConvertError::Malformed(e.to_string()));
    }
    let Some(order) = yuv422_order(&enc) else {
        return Err(ConvertError::UnsupportedEncoding(msg.encoding.clone()));
    };
    if w % 2 != 0 || step < 2 * w {
        return Err(ConvertError::Malformed(format!(
            "{} needs an even width and step ≥ 2×width, got width {w}, step {step}",
            msg.encoding
        )));
    }
    buf.rgb.resize(w * h * 3, 0);
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

/// A [`Frame`] of a decoded `sensor_msgs/CompressedImage` (JPEG or PNG).
///
/// # Errors
/// [`ConvertError`] for other formats, corrupt data, or images larger than
/// [`MAX_DECODED_BYTES`] / [`MAX_FRAME_SIDE`] (checked from the header before decoding).
pub fn frame_from_compressed<'a>(
    msg: &CompressedImage,
    buf: &'a mut PixelBuffer,
) -> Result<Frame<'a>, ConvertError> {
    let fmt = msg.format.to_ascii_lowercase();
    let kind = if fmt.contains("jpeg") || fmt.contains("jpg") {
        image::ImageFormat::Jpeg
    } else if fmt.contains("png") {
        image::ImageFormat::Png
    } else {
        return Err(ConvertError::UnsupportedEncoding(msg.format.clone()));
    };
    let err = |e: &dyn std::fmt::Display| ConvertError::Decode {
        format: msg.format.clone(),
        reason: e.to_string(),
    };
    let mut reader = image::ImageReader::with_format(std::io::Cursor::new(&msg.data), kind);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_FRAME_SIDE as u32);
    limits.max_image_height = Some(MAX_FRAME_SIDE as u32);
    limits.max_alloc = Some(MAX_DECODED_BYTES);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| err(&e))?.into_rgb8();
    let (w, h) = check_geometry(img.width(), img.height())?;
    buf.rgb = img.into_raw();
    Frame::packed(&buf.rgb, w, h, PixelFormat::Rgb8)
        .map_err(|e| ConvertError::Malformed(e.to_string()))
}

/// `vision_msgs/Detection2DArray` for one tracker output: the box (centre, size), the
/// consensus score as the hypothesis score, the track id as `id`.
pub fn detections_from_output(
    header: &Header,
    out: Option<&TrackOutput>,
    track_id: u32,
    class_id: &str,
) -> Detection2DArray {
    let detections = out
        .map(|o| {
            let c = o.bbox.center();
            vec![Detection2D {
                header: header.clone(),
                results: vec![ObjectHypothesisWithPose {
                    hypothesis: ObjectHypothesis {
                        class_id: class_id.to_string(),
                        score: o.consensus as f64,
                    },
                    pose: PoseWithCovariance::default(),
                }],
                bbox: BoundingBox2D {
                    center: Pose2D {
                        position: Point2D {
                            x: c.x as f64,
                            y: c.y as f64,
                        },
                        theta: 0.0,
                    },
                    size_x: o.bbox.w as f64,
                    size_y: o.bbox.h as f64,
                },
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
        let f = frame_from_image(&m, &mut b).unwrap();
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
                    frame_from_image(&m, &mut b),
                    Err(ConvertError::Malformed(_))
                ),
                "{m:?}"
            );
        }
    }

    #[test]
    fn unsupported_encodings_are_named() {
        let mut b = PixelBuffer::default();
        let e = frame_from_image(&img("16UC1", 1, 1, 2, vec![0; 2]), &mut b).unwrap_err();
        assert!(e.to_string().contains("16UC1"), "{e}");
    }

    #[test]
    fn yuv422_variants_decode_grey_and_colour() {
        let mut b = PixelBuffer::default();
        // UYVY: mid grey (Y=126, U=V=128) → about 128 on every channel.
        let m = img("yuv422", 2, 1, 4, vec![128, 126, 128, 126]);
        let f = frame_from_image(&m, &mut b).unwrap();
        assert!(
            f.data()[..6].iter().all(|&v| (v as i32 - 128).abs() <= 1),
            "{:?}",
            &f.data()[..6]
        );
        // YUYV: saturated red (Y=81, U=90, V=240).
        let m = img("yuv422_yuy2", 2, 1, 4, vec![81, 90, 81, 240]);
        let f = frame_from_image(&m, &mut b).unwrap();
        let px = &f.data()[..3];
        assert!(px[0] > 240 && px[1] < 15 && px[2] < 15, "{px:?}");
        assert!(frame_from_image(&img("yuv422", 3, 1, 6, vec![0; 6]), &mut b).is_err());
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
        let f = frame_from_compressed(&m, &mut b).unwrap();
        assert_eq!((f.width(), f.height()), (4, 3));
        assert_eq!(&f.data()[..3], &[10, 20, 30]);
        let bad = CompressedImage {
            format: "rgb8; jpeg compressed bgr8".into(),
            data: vec![0xFF, 0xD8, 0x00, 0x01],
            ..Default::default()
        };
        assert!(matches!(
            frame_from_compressed(&bad, &mut b),
            Err(ConvertError::Decode { .. })
        ));
        let tiff = CompressedImage {
            format: "tiff".into(),
            ..Default::default()
        };
        assert!(matches!(
            frame_from_compressed(&tiff, &mut b),
            Err(ConvertError::UnsupportedEncoding(_))
        ));
    }

    #[test]
    fn detection_round_trips_the_box_and_carries_the_score() {
        let out = TrackOutput {
            bbox: BBox::new(10.0, 20.0, 30.0, 40.0),
            consensus: 0.9,
            learned: true,
            peak: 0.1,
            scale: 1.0,
        };
        let d = detections_from_output(&Header::default(), Some(&out), 3, "target");
        assert_eq!(d.detections.len(), 1);
        assert_eq!(bbox_from_detection(&d.detections[0]), out.bbox);
        assert!((d.detections[0].results[0].hypothesis.score - 0.9).abs() < 1e-6);
        assert_eq!(d.detections[0].id, "3");
        assert!(detections_from_output(&Header::default(), None, 3, "t")
            .detections
            .is_empty());
    }
}
