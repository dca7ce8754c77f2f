//! Precision and success plots (PNG) in the style of the OTB/UAV123 figures: one curve per
//! tracker, the legend sorted by score and showing it (precision at 20 px, success AUC).

use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::OnceLock;

/// Plot size, pixels.
const SIZE: (u32, u32) = (900, 680);
/// Our tracker's curve is drawn thicker than the peers'.
const OWN_STROKE: u32 = 4;
/// Peers' stroke width.
const PEER_STROKE: u32 = 2;

/// One curve: tracker name, its headline score, its samples.
#[derive(Debug, Clone)]
pub struct Curve {
    /// Tracker name.
    pub name: String,
    /// Headline score shown in the legend.
    pub score: f64,
    /// Samples at evenly spaced thresholds.
    pub values: Vec<f64>,
    /// Draw emphasised (our tracker).
    pub own: bool,
}

/// Registers the embedded DejaVu Sans font once (no system fonts are needed).
fn ensure_font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .map_err(|_| "the embedded font could not be loaded".to_string())
    })
    .clone()
}

const PALETTE: [RGBColor; 10] = [
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Draws curves over thresholds `0..=x_max` into a PNG.
///
/// # Errors
/// A message when drawing or writing fails.
pub fn plot_curves(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    x_max: f64,
    curves: &[Curve],
) -> Result<(), String> {
    ensure_font()?;
    let mut sorted: Vec<&Curve> = curves.iter().collect();
    sorted.sort_by(|a, b| b.score.total_cmp(&a.score));
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    let e = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 26))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x_max, 0.0..1.0)
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style(("sans-serif", 16))
        .draw()
        .map_err(|x| e(&x))?;
    let mut peer = 1usize;
    for c in sorted {
        let color = if c.own {
            PALETTE[0]
        } else {
            // Peers cycle through every colour but ours.
            let col = PALETTE[1 + (peer - 1) % (PALETTE.len() - 1)];
            peer += 1;
            col
        };
        let n = c.values.len().max(2) - 1;
        let pts: Vec<(f64, f64)> = c
            .values
            .iter()
            .enumerate()
            .map(|(i, &v)| (x_max * i as f64 / n as f64, v))
            .collect();
        let stroke = if c.own { OWN_STROKE } else { PEER_STROKE };
        let style = color.stroke_width(stroke);
        chart
            .draw_series(LineSeries::new(pts, style))
            .map_err(|x| e(&x))?
            .label(format!("{} [{:.3}]", c.name, c.score))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(stroke))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_png_with_the_legend() -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("bevt_plot_{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let p = dir.join("success.png");
        let curves = vec![
            Curve {
                name: "A".into(),
                score: 0.5,
                values: vec![1.0, 0.5, 0.0],
                own: true,
            },
            Curve {
                name: "B".into(),
                score: 0.3,
                values: vec![0.9, 0.2, 0.0],
                own: false,
            },
        ];
        plot_curves(
            &p,
            "Success plot",
            "overlap threshold",
            "success rate",
            1.0,
            &curves,
        )?;
        let img = image::open(&p)?;
        assert_eq!((img.width(), img.height()), SIZE);
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }
}
