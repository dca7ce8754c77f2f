//! Precision and success plots (PNG) in the style of the OTB/UAV123 figures: one curve per
//! tracker, the legend sorted by score and showing it (precision at 20 px, success AUC).
//!
//! The legend is drawn beside the chart, never over it, one row per tracker with its swatch
//! on the row's centre line (plotters' own legend box drifts away from its labels when it
//! holds dozens of entries). Our curve is red, thick and drawn last (on top); peers cycle
//! through nine colours and, after each cycle, a new dash pattern, so that every entry of a
//! 30-tracker comparison is told apart, and keep their style from one plot to the other.

use plotters::coord::CoordTranslate;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::OnceLock;

/// Chart size (axes and curves), pixels; the legend widens the image to its right.
const SIZE: (u32, u32) = (900, 680);
/// Legend text size, pixels.
const LEGEND_FONT: u32 = 14;
/// Height of one legend row, pixels.
const ROW_H: i32 = 18;
/// Length of a legend swatch, pixels.
const SWATCH: i32 = 30;
/// Gap between a swatch and its label, pixels.
const GAP: i32 = 6;
/// Padding around the legend and between its columns, pixels.
const PAD: i32 = 12;
/// Top of the first legend row (level with the chart's top axis), pixels.
const LEGEND_TOP: i32 = 52;
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

/// Line pattern of a curve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dash {
    /// Continuous.
    Solid,
    /// 10 px dashes.
    Dashed,
    /// 3 px dots.
    Dotted,
    /// 18 px dashes.
    LongDash,
}

impl Dash {
    /// (dash, gap) lengths in pixels; `None` for a solid line.
    fn pattern(self) -> Option<(i32, i32)> {
        match self {
            Dash::Solid => None,
            Dash::Dashed => Some((10, 6)),
            Dash::Dotted => Some((3, 4)),
            Dash::LongDash => Some((18, 5)),
        }
    }
}

/// How a curve is drawn; its legend swatch is drawn the same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeriesStyle {
    /// RGB colour.
    pub color: (u8, u8, u8),
    /// Stroke width, pixels.
    pub stroke: u32,
    /// Line pattern.
    pub dash: Dash,
}

impl SeriesStyle {
    fn rgb(&self) -> RGBColor {
        RGBColor(self.color.0, self.color.1, self.color.2)
    }
}

/// Indices of `curves` from the highest score to the lowest (the legend's order).
fn by_score(curves: &[Curve]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..curves.len()).collect();
    order.sort_by(|&a, &b| curves[b].score.total_cmp(&curves[a].score));
    order
}

/// The style of each curve, in the order of `curves`: ours red and thick; peers, in the
/// order given (so a tracker keeps its style in the precision and the success plot), cycle
/// through the other nine colours, with a new dash pattern per cycle.
pub fn series_styles(curves: &[Curve]) -> Vec<SeriesStyle> {
    let mut peer = 0usize;
    curves
        .iter()
        .map(|c| {
            if c.own {
                let RGBColor(r, g, b) = PALETTE[0];
                return SeriesStyle {
                    color: (r, g, b),
                    stroke: OWN_STROKE,
                    dash: Dash::Solid,
                };
            }
            let colours = PALETTE.len() - 1;
            let RGBColor(r, g, b) = PALETTE[1 + peer % colours];
            let dash =
                [Dash::Solid, Dash::Dashed, Dash::Dotted, Dash::LongDash][(peer / colours) % 4];
            peer += 1;
            SeriesStyle {
                color: (r, g, b),
                stroke: PEER_STROKE,
                dash,
            }
        })
        .collect()
}

/// One legend row as drawn.
#[derive(Debug, Clone, PartialEq)]
pub struct LegendEntry {
    /// `name [score]`.
    pub label: String,
    /// The curve's style (the swatch's).
    pub style: SeriesStyle,
    /// Left end of the swatch, image pixels.
    pub x: i32,
    /// The row's centre line (swatch and text), image pixels.
    pub y: i32,
}

/// The legend of a plot: its rows in order (highest score first) and the image width.
#[derive(Debug, Clone, PartialEq)]
pub struct Legend {
    /// Rows, highest score first, column by column.
    pub entries: Vec<LegendEntry>,
    /// Width of the whole image (chart plus legend), pixels.
    pub image_width: u32,
}

/// Lays the legend out to the right of the chart: as many rows per column as fit in the
/// chart's height, as many columns as needed. `text_width` measures a label in pixels.
fn legend_layout(curves: &[Curve], text_width: impl Fn(&str) -> u32) -> Legend {
    let styles = series_styles(curves);
    let rows = ((SIZE.1 as i32 - LEGEND_TOP - PAD) / ROW_H).max(1) as usize;
    let order = by_score(curves);
    let mut entries = Vec::with_capacity(order.len());
    let mut x = SIZE.0 as i32;
    for column in order.chunks(rows) {
        let labels: Vec<String> = column
            .iter()
            .map(|&i| format!("{} [{:.3}]", curves[i].name, curves[i].score))
            .collect();
        let widest = labels.iter().map(|l| text_width(l)).max().unwrap_or(0) as i32;
        for (row, (&i, label)) in column.iter().zip(labels).enumerate() {
            entries.push(LegendEntry {
                label,
                style: styles[i],
                x,
                y: LEGEND_TOP + ROW_H * row as i32 + ROW_H / 2,
            });
        }
        x += SWATCH + GAP + widest + PAD;
    }
    Legend {
        entries,
        image_width: (x + PAD) as u32,
    }
}

/// Draws `points` (pixels or chart coordinates) with `style` on `area`.
fn draw_styled<DB, CT>(
    area: &DrawingArea<DB, CT>,
    points: Vec<CT::From>,
    style: &SeriesStyle,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend,
    CT: CoordTranslate,
    CT::From: Clone,
{
    let shape = style.rgb().stroke_width(style.stroke);
    match style.dash.pattern() {
        None => area.draw(&PathElement::new(points, shape)),
        Some((dash, gap)) => area.draw(&DashedPathElement::new(points, dash, gap, shape)),
    }
}

/// Draws curves over thresholds `0..=x_max` into a PNG, with the legend beside the chart.
/// Returns the legend as drawn.
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
) -> Result<Legend, String> {
    ensure_font()?;
    let font = ("sans-serif", LEGEND_FONT).into_font();
    let legend = legend_layout(curves, |t| {
        font.box_size(t).map_or(8 * t.len() as u32, |s| s.0)
    });
    let e = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    // Drawn into memory and written with the `image` crate the tool already uses for frames:
    // plotters' own PNG encoder would build a second, older `image` and `png` (issue 18's
    // first build). The size is the legend's layout's: bounded by the number of curves.
    let (width, height) = (legend.image_width, SIZE.1);
    let styles = series_styles(curves);
    let draw = |pixels: &mut [u8]| -> Result<(), String> {
        let root = BitMapBackend::with_buffer(pixels, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let (chart_area, _) = root.split_horizontally(SIZE.0);
        let mut chart = ChartBuilder::on(&chart_area)
            .caption(title, ("sans-serif", 26))
            .margin(16)
            // Room for the last x tick label, which would be clipped at the legend's edge.
            .margin_right(28)
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
        let plotting = chart.plotting_area();
        // Peers from the lowest score up, ours last: the emphasised curve stays on top.
        let mut order = by_score(curves);
        order.reverse();
        order.sort_by_key(|&i| curves[i].own);
        for i in order {
            let c = &curves[i];
            let n = c.values.len().max(2) - 1;
            let pts: Vec<(f64, f64)> = c
                .values
                .iter()
                .enumerate()
                .map(|(k, &v)| (x_max * k as f64 / n as f64, v))
                .collect();
            draw_styled(plotting, pts, &styles[i]).map_err(|x| e(&x))?;
        }
        for entry in &legend.entries {
            let swatch = vec![(entry.x, entry.y), (entry.x + SWATCH, entry.y)];
            draw_styled(&root, swatch, &entry.style).map_err(|x| e(&x))?;
            let style = font.color(&BLACK).pos(Pos::new(HPos::Left, VPos::Center));
            root.draw(&Text::new(
                entry.label.clone(),
                (entry.x + SWATCH + GAP, entry.y),
                style,
            ))
            .map_err(|x| e(&x))?;
        }
        root.present().map_err(|x| e(&x))
    };
    let mut pixels = vec![0u8; width as usize * height as usize * 3];
    draw(&mut pixels)?;
    let image = image::RgbImage::from_raw(width, height, pixels)
        .ok_or_else(|| e(&"plot buffer does not match its size"))?;
    image
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|x| e(&x))?;
    Ok(legend)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(name: &str, score: f64, own: bool) -> Curve {
        // Steep, never flat: no curve pixel run is as long as a swatch.
        Curve {
            name: name.into(),
            score,
            values: (0..=20)
                .map(|i| (i as f64 * score / 20.0).min(1.0))
                .collect(),
            own,
        }
    }

    #[test]
    fn legend_rows_match_their_curves_and_sit_beside_the_chart(
    ) -> Result<(), Box<dyn std::error::Error>> {
        let dir = std::env::temp_dir().join(format!("bevt_plot_{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let p = dir.join("success.png");
        // Ours is neither first given nor first by score; 37 entries need two columns.
        let mut curves = vec![curve("peer-b", 0.4, false), curve("ours", 0.7, true)];
        curves.push(curve("peer-a", 0.9, false));
        for i in 0..34 {
            curves.push(curve(&format!("p{i}"), 0.3 - i as f64 * 0.005, false));
        }
        let legend = plot_curves(&p, "Success plot", "overlap", "success rate", 1.0, &curves)?;
        let labels: Vec<&str> = legend.entries.iter().map(|e| e.label.as_str()).collect();
        assert_eq!(
            &labels[..3],
            ["peer-a [0.900]", "ours [0.700]", "peer-b [0.400]"]
        );
        // Each row carries the style its curve is drawn with; ours is the red thick one.
        let styles = series_styles(&curves);
        for (e, &i) in legend.entries.iter().zip(&by_score(&curves)) {
            assert!(e.label.starts_with(&curves[i].name), "{}", e.label);
            assert_eq!(e.style, styles[i], "{}", e.label);
        }
        assert_eq!(legend.entries[1].style.color, (214, 39, 40));
        assert_eq!(legend.entries[1].style.stroke, OWN_STROKE);
        // A tracker keeps its style when its rank changes (precision vs success plot).
        let mut reranked = curves.clone();
        reranked[0].score = 0.95;
        assert_eq!(series_styles(&reranked), styles);
        // Peers that share a colour differ in dash pattern.
        let peers: Vec<SeriesStyle> = styles
            .iter()
            .zip(&curves)
            .filter(|(_, c)| !c.own)
            .map(|(s, _)| *s)
            .collect();
        for (i, a) in peers.iter().enumerate() {
            for b in &peers[i + 1..] {
                assert!((a.color, a.dash) != (b.color, b.dash), "{a:?}");
            }
        }
        let columns: std::collections::BTreeSet<i32> = legend.entries.iter().map(|e| e.x).collect();
        assert_eq!(columns.len(), 2);
        let img = image::open(&p)?.to_rgb8();
        assert_eq!(img.height(), SIZE.1);
        assert_eq!(img.width(), legend.image_width);
        let px = |x: i32, y: i32| img.get_pixel(x as u32, y as u32).0;
        for e in &legend.entries {
            // Beside the chart, inside the image.
            assert!(e.x >= SIZE.0 as i32 && e.x + SWATCH < img.width() as i32);
            assert!(e.y + ROW_H / 2 <= SIZE.1 as i32);
            // The swatch's start is drawn in the entry's colour on the row's centre line...
            let (r, g, b) = e.style.color;
            assert_eq!(px(e.x + 1, e.y), [r, g, b], "{}", e.label);
            // ...and the label's ink is centred on the same line.
            let x0 = e.x + SWATCH + GAP;
            let ink: Vec<i32> = (e.y - ROW_H / 2..e.y + ROW_H / 2)
                .filter(|&y| (x0..x0 + 30).any(|x| px(x, y).iter().all(|&c| c < 110)))
                .collect();
            let (top, bottom) = (ink.first().copied(), ink.last().copied());
            let (Some(top), Some(bottom)) = (top, bottom) else {
                panic!("{}: no text on row {}", e.label, e.y);
            };
            assert!(
                ((top + bottom) / 2 - e.y).abs() <= 3,
                "{}: text rows {top}..={bottom}, swatch row {}",
                e.label,
                e.y
            );
        }
        std::fs::remove_dir_all(&dir)?;
        Ok(())
    }
}
