//! Tracks one sequence of JPEG frames with the default tracker (the embedded networks
//! included) and writes its boxes and track states in `bevt eval`'s formats: the same
//! computation on two architectures, for `scripts/test-aarch64.sh`, which runs it natively
//! and under qemu-aarch64 and compares the two outputs. No ROS, no dataset layout: the
//! script resolves the frames and the initial box.
//!
//! `track_sequence <out prefix> <x,y,w,h> <frame.jpg>...`
//!
//! - the box is the first frame's, as in a UAV123 annotation row (1-based pixels);
//! - `<out prefix>.txt` (created: an existing file is an error) gets one `x,y,w,h` row per frame (1-based, two decimals; the first
//!   the initial box), `<out prefix>.state.csv` one `frame,confidence,state,reason` row.
//!
//! Every failure (an unreadable or undecodable frame, a frame of another size, a bad box,
//! a tracker error) ends the program with a message and exit status 1.

use bevt_core::{BBox, BevtTracker, Frame, PixelFormat, Tracker, TrackerConfig};
use std::fmt::Write as _;
use std::path::Path;
use std::process::ExitCode;

/// A decoded frame: packed RGB, width, height.
type Rgb = (Vec<u8>, usize, usize);

fn decode(path: &Path) -> Result<Rgb, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut d = zune_jpeg::JpegDecoder::new(std::io::Cursor::new(bytes));
    let pixels = d
        .decode()
        .map_err(|e| format!("{}: not a decodable JPEG: {e:?}", path.display()))?;
    let (w, h) = d
        .dimensions()
        .ok_or_else(|| format!("{}: no image size", path.display()))?;
    if pixels.len() != w * h * 3 {
        return Err(format!(
            "{}: {} bytes for {w}×{h}, not RGB",
            path.display(),
            pixels.len()
        ));
    }
    Ok((pixels, w, h))
}

fn parse_box(s: &str) -> Result<BBox, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("box '{s}': {e}"))?;
    match v[..] {
        [x, y, w, h] => Ok(BBox {
            x: x - 1.0,
            y: y - 1.0,
            w,
            h,
        }),
        _ => Err(format!("box '{s}': not x,y,w,h")),
    }
}

fn row(b: &BBox) -> String {
    format!("{:.2},{:.2},{:.2},{:.2}\n", b.x + 1.0, b.y + 1.0, b.w, b.h)
}

fn run(args: &[String]) -> Result<(), String> {
    let [prefix, init, frames @ ..] = args else {
        return Err("usage: track_sequence <out prefix> <x,y,w,h> <frame.jpg>...".into());
    };
    if frames.is_empty() {
        return Err("no frames".into());
    }
    let init = parse_box(init)?;
    let spec = TrackerConfig::default()
        .validate()
        .map_err(|e| format!("default configuration: {e}"))?;
    let mut tracker = BevtTracker::new(spec);
    let (mut boxes, mut states) = (row(&init), String::from("frame,confidence,state,reason\n"));
    let mut size = None;
    for (i, path) in frames.iter().enumerate() {
        let (rgb, w, h) = decode(Path::new(path))?;
        if *size.get_or_insert((w, h)) != (w, h) {
            return Err(format!("{path}: {w}×{h}, not the first frame's size"));
        }
        let frame =
            Frame::packed(&rgb, w, h, PixelFormat::Rgb8).map_err(|e| format!("{path}: {e}"))?;
        if i == 0 {
            tracker
                .init(&frame, init)
                .map_err(|e| format!("{path}: init: {e}"))?;
            states.push_str("1,,init,\n");
            continue;
        }
        let o = tracker.update(&frame).map_err(|e| format!("{path}: {e}"))?;
        boxes.push_str(&row(&o.bbox));
        let _ = writeln!(
            states,
            "{},{:.4},{},\"{}\"",
            i + 1,
            o.confidence,
            o.state.name(),
            o.reason.to_string().replace('"', "'")
        );
    }
    // A new file each: an existing one is an error, never overwritten.
    let write = |ext: &str, s: &str| {
        let p = format!("{prefix}.{ext}");
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&p)
            .and_then(|mut f| std::io::Write::write_all(&mut f, s.as_bytes()))
            .map_err(|e| format!("{p}: {e}"))
    };
    write("txt", &boxes)?;
    write("state.csv", &states)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("track_sequence: {e}");
            ExitCode::FAILURE
        }
    }
}
