//! Drawing a figure: a [`FigureContent`] (panels of median curves with interquartile bands, shared axis labels,
//! one legend) rendered with `plotters` to `NAME.png` and `NAME.svg` by [`draw_figure`]. Text is drawn with the
//! DejaVu Sans font embedded in the binary (assets/), so no system font library is needed. Which figures the
//! paper has and what goes into them is [`super::figures`]' business.

use anyhow::{Context, Result, anyhow};
use arld_core::files::write_atomic;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontStyle, register_font};
use std::path::{Path, PathBuf};
use std::sync::Once;

/// DejaVu Sans (Bitstream Vera license, see assets/DejaVuSans-LICENSE.txt).
static FONT_BYTES: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");
const FONT_FAMILY: &str = "sans-serif";

fn ensure_font() -> Result<()> {
    static REGISTER: Once = Once::new();
    let mut result = Ok(());
    REGISTER.call_once(|| {
        if register_font(FONT_FAMILY, FontStyle::Normal, FONT_BYTES).is_err() {
            result = Err(anyhow!("the embedded font could not be loaded"));
        }
    });
    result
}

/// Summary of several seeds at one x position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    pub x: f64,
    pub median: f64,
    pub lower_quartile: f64,
    pub upper_quartile: f64,
}

/// One line of a panel with its interquartile band; `color` indexes [`PALETTE`] and, past its length, the same
/// colours again dashed, then dotted ([`line_style`]).
#[derive(Debug, Clone)]
pub struct Curve {
    pub label: String,
    pub color: usize,
    pub points: Vec<Band>,
}

/// One plot of a figure.
#[derive(Debug, Clone)]
pub struct Panel {
    pub title: String,
    /// Score that solves the task, drawn as a dashed horizontal line.
    pub threshold: Option<f64>,
    pub curves: Vec<Curve>,
}

impl Panel {
    pub fn new(title: String, threshold: Option<f64>, curves: Vec<Curve>) -> Self {
        Panel {
            title,
            threshold,
            curves,
        }
    }
}

/// How a figure's x values read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum XScale {
    /// Environment steps from 0 to the last x, ticks as 2.5k, 200k, 1.5M.
    #[default]
    Steps,
    /// The base-2 logarithm of a multiple (of a budget, say): ticks at whole powers of two read 1/4, 1/2, 1, 2, 4.
    Log2Multiple,
    /// The base-10 logarithm of environment steps: ticks at whole powers of ten read 10, 100, 1k, 10k.
    Log10Steps,
}

impl XScale {
    /// The x range a panel spans, from the largest and smallest x of its points.
    fn range(self, x_min: f64, x_max: f64) -> (f64, f64) {
        match self {
            XScale::Steps => (0.0, if x_max > 0.0 { x_max } else { 1.0 }),
            XScale::Log2Multiple if x_min <= x_max => (x_min - 0.25, x_max + 0.25),
            XScale::Log2Multiple => (-1.0, 1.0),
            XScale::Log10Steps if x_min <= x_max => (x_min.floor(), x_max),
            XScale::Log10Steps => (1.0, 2.0),
        }
    }

    /// Tick text at `x`.
    fn label(self, x: f64) -> String {
        match self {
            XScale::Steps => format_steps(x),
            XScale::Log2Multiple if (x - x.round()).abs() > 1e-9 => String::new(),
            XScale::Log2Multiple if x < 0.0 => format!("1/{}", 2f64.powf(-x.round())),
            XScale::Log2Multiple => format!("{}", 2f64.powf(x.round())),
            XScale::Log10Steps if (x - x.round()).abs() > 1e-9 => String::new(),
            XScale::Log10Steps => format_steps(10f64.powf(x.round())),
        }
    }

    /// How many x ticks to ask for over `span`.
    fn ticks(self, span: f64) -> usize {
        match self {
            XScale::Steps => 6,
            XScale::Log2Multiple | XScale::Log10Steps => (span.floor() as usize + 1).max(2),
        }
    }
}

/// A figure: a row (or grid) of panels sharing axis labels and one legend.
#[derive(Debug, Clone)]
pub struct FigureContent {
    pub title: String,
    pub x_label: String,
    pub x_scale: XScale,
    pub y_label: String,
    pub panels: Vec<Panel>,
}

/// Line colours (Okabe-Ito, readable with colour-vision deficiencies); a [`Curve`]'s `color` indexes them.
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(90, 90, 90),    // DQN: grey
    RGBColor(230, 159, 0),   // GDQN: orange
    RGBColor(86, 180, 233),  // BDQN: sky blue
    RGBColor(213, 94, 0),    // ADQN: vermillion
    RGBColor(0, 114, 178),   // DQfD: blue
    RGBColor(0, 158, 115),   // ADQNP: green
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(0, 0, 0),       // black
];

/// Line patterns (dash, gap in pixels; `None`: solid), in the order [`line_style`] takes them.
const PATTERNS: [Option<(u32, u32)>; 4] = [None, Some((10, 6)), Some((2, 4)), Some((18, 5))];

/// The palette's colours in the order that keeps the first few of a panel far apart (black, orange, sky blue,
/// green, reddish purple, blue, vermillion, grey).
const DISTINCT_ORDER: [usize; 8] = [7, 1, 2, 5, 6, 4, 3, 0];

/// The style of member `member` of family `family` of a figure whose panels each show one family: the family's
/// own pattern, and the colours of [`DISTINCT_ORDER`] in turn, so the curves of a panel differ in colour and no
/// two curves of the figure look alike (for up to 8 members of up to 4 families).
pub fn family_style(family: usize, member: usize) -> usize {
    (family % PATTERNS.len()) * PALETTE.len() + DISTINCT_ORDER[member % DISTINCT_ORDER.len()]
}

/// The colour of style `index` and its dash pattern (dash, gap in pixels; `None`: solid): the palette's colours
/// solid, then dashed, then dotted, then long-dashed, then solid again.
fn line_style(index: usize) -> (RGBColor, Option<(u32, u32)>) {
    (
        PALETTE[index % PALETTE.len()],
        PATTERNS[(index / PALETTE.len()) % PATTERNS.len()],
    )
}

/// Axis tick text for environment steps: 500, 2.5k, 200k, 1.5M.
fn format_steps(value: f64) -> String {
    let trim = |v: f64| {
        let text = format!("{v:.1}");
        text.strip_suffix(".0").map(str::to_string).unwrap_or(text)
    };
    match value.abs() {
        v if v >= 1e6 => format!("{}M", trim(value / 1e6)),
        v if v >= 1e3 => format!("{}k", trim(value / 1e3)),
        _ => trim(value),
    }
}

/// A y-axis label for `value` on an axis spanning `span`: as [`format_steps`] where the ticks are a unit or more
/// apart, else with the decimals that tell neighbouring ticks (about a seventh of the span) apart.
fn format_axis(value: f64, span: f64) -> String {
    let tick = span / 7.0;
    if !(tick.is_finite() && tick > 0.0) || tick >= 1.0 {
        return format_steps(value);
    }
    let decimals = (-tick.log10()).ceil().clamp(1.0, 6.0) as usize;
    format!("{value:.decimals$}")
}

/// Axis ranges of a panel: x as `x_scale` spans its points, y covering bands and threshold with 5% padding.
fn panel_ranges(panel: &Panel, x_scale: XScale) -> ((f64, f64), (f64, f64)) {
    let points = panel.curves.iter().flat_map(|c| c.points.iter());
    let x_max = points
        .clone()
        .map(|p| p.x)
        .fold(f64::NEG_INFINITY, f64::max);
    let x_min = points.clone().map(|p| p.x).fold(f64::INFINITY, f64::min);
    let mut y_min = points
        .clone()
        .map(|p| p.lower_quartile.min(p.median))
        .fold(f64::INFINITY, f64::min);
    let mut y_max = points
        .map(|p| p.upper_quartile.max(p.median))
        .fold(f64::NEG_INFINITY, f64::max);
    if let Some(t) = panel.threshold {
        y_min = y_min.min(t);
        y_max = y_max.max(t);
    }
    if !y_min.is_finite() || !y_max.is_finite() {
        (y_min, y_max) = (0.0, 1.0);
    }
    let pad = if y_max > y_min {
        0.05 * (y_max - y_min)
    } else {
        1.0
    };
    (x_scale.range(x_min, x_max), (y_min - pad, y_max + pad))
}

const PANEL_WIDTH: u32 = 560;
const PANEL_HEIGHT: u32 = 420;
const TITLE_HEIGHT: u32 = 50;
const TITLE_FONT: u32 = 24;
const LEGEND_FONT: u32 = 17;
const LEGEND_ROW_HEIGHT: u32 = 32;
const LEGEND_PADDING: u32 = 12;
/// Horizontal room around the title and the legend rows.
const SIDE_ROOM: u32 = 40;
/// A legend row never grows wider than this; further entries wrap to a new row.
const MAX_LEGEND_ROW: u32 = 1400;
const SWATCH: u32 = 36;
const SWATCH_GAP: u32 = 10;
const ENTRY_SPACING: u32 = 34;

/// One legend entry: its text and its colour, or `None` for the dashed threshold line.
struct LegendEntry {
    label: String,
    color: Option<usize>,
    width: u32,
}

/// Where everything goes, measured before drawing so the figure is as wide as its title and legend need.
struct Layout {
    size: (u32, u32),
    grid: (usize, usize),
    /// Width of the block of panels, centred in the figure.
    panels_width: u32,
    /// Legend entries per row.
    legend_rows: Vec<Vec<LegendEntry>>,
}

fn text_width(text: &str, size: u32) -> Result<u32> {
    Ok((FONT_FAMILY, size as f64)
        .into_font()
        .box_size(text)
        .map_err(plot_error)?
        .0)
}

fn layout(figure: &FigureContent) -> Result<Layout> {
    let n = figure.panels.len().max(1);
    let cols = n.min(4);
    let rows = n.div_ceil(cols);
    let panels_width = PANEL_WIDTH * cols as u32;

    // Every curve label once, in order of appearance, then the threshold line if any panel has one.
    let mut entries: Vec<LegendEntry> = Vec::new();
    for curve in figure.panels.iter().flat_map(|p| &p.curves) {
        if !entries.iter().any(|e| e.label == curve.label) {
            let width = SWATCH + SWATCH_GAP + text_width(&curve.label, LEGEND_FONT)?;
            entries.push(LegendEntry {
                label: curve.label.clone(),
                color: Some(curve.color),
                width,
            });
        }
    }
    if figure.panels.iter().any(|p| p.threshold.is_some()) {
        let label = "solve threshold".to_string();
        let width = SWATCH + SWATCH_GAP + text_width(&label, LEGEND_FONT)?;
        entries.push(LegendEntry {
            label,
            color: None,
            width,
        });
    }
    let one_row: u32 = entries
        .iter()
        .map(|e| e.width + ENTRY_SPACING)
        .sum::<u32>()
        .saturating_sub(ENTRY_SPACING);
    let title_width = text_width(&figure.title, TITLE_FONT)?;
    let width = panels_width
        .max(title_width + 2 * SIDE_ROOM)
        .max(one_row.min(MAX_LEGEND_ROW) + 2 * SIDE_ROOM);

    let row_limit = width - 2 * SIDE_ROOM;
    let mut legend_rows: Vec<Vec<LegendEntry>> = Vec::new();
    let mut row_width = 0;
    for entry in entries {
        let needed = if row_width == 0 {
            entry.width
        } else {
            row_width + ENTRY_SPACING + entry.width
        };
        match legend_rows.last_mut() {
            Some(row) if needed <= row_limit => {
                row_width = needed;
                row.push(entry);
            }
            _ => {
                row_width = entry.width;
                legend_rows.push(vec![entry]);
            }
        }
    }
    let legend_height = legend_rows.len() as u32 * LEGEND_ROW_HEIGHT + 2 * LEGEND_PADDING;
    Ok(Layout {
        size: (
            width,
            PANEL_HEIGHT * rows as u32 + TITLE_HEIGHT + legend_height,
        ),
        grid: (rows, cols),
        panels_width,
        legend_rows,
    })
}

fn plot_error<E: std::fmt::Debug>(err: E) -> anyhow::Error {
    anyhow!("plotting failed: {err:?}")
}

/// Draws the whole figure on a drawing area of any backend (bitmap or SVG).
fn draw_on<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    figure: &FigureContent,
    layout: &Layout,
) -> Result<()> {
    root.fill(&WHITE).map_err(plot_error)?;
    let (width, height) = layout.size;
    let (title_area, rest) = root.split_vertically(TITLE_HEIGHT);
    let legend_height = height - TITLE_HEIGHT - PANEL_HEIGHT * layout.grid.0 as u32;
    let (plot_area, legend_area) = rest.split_vertically(height - TITLE_HEIGHT - legend_height);
    let title_style = TextStyle::from((FONT_FAMILY, TITLE_FONT as f64).into_font())
        .pos(Pos::new(HPos::Center, VPos::Center));
    title_area
        .draw(&Text::new(
            figure.title.clone(),
            (width as i32 / 2, TITLE_HEIGHT as i32 / 2),
            title_style,
        ))
        .map_err(plot_error)?;
    // Panels keep their size; a figure widened for its title or legend centres them.
    let side = (width - layout.panels_width) / 2;
    let plot_area = plot_area.margin(0, 0, side, width - layout.panels_width - side);

    for (area, panel) in plot_area
        .split_evenly(layout.grid)
        .iter()
        .zip(&figure.panels)
    {
        let ((x_min, x_max), (y_min, y_max)) = panel_ranges(panel, figure.x_scale);
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, (FONT_FAMILY, 19))
            .margin_top(6)
            .margin_left(8)
            .margin_right(22)
            .margin_bottom(6)
            .x_label_area_size(52)
            .y_label_area_size(74)
            .build_cartesian_2d(x_min..x_max, y_min..y_max)
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .x_desc(figure.x_label.as_str())
            .y_desc(figure.y_label.as_str())
            .x_labels(figure.x_scale.ticks(x_max - x_min))
            .y_labels(7)
            .x_label_formatter(&|x| figure.x_scale.label(*x))
            .y_label_formatter(&|y| format_axis(*y, y_max - y_min))
            .label_style((FONT_FAMILY, 14))
            .axis_desc_style((FONT_FAMILY, 16))
            .bold_line_style(RGBColor(225, 225, 225))
            .light_line_style(RGBColor(245, 245, 245))
            .draw()
            .map_err(plot_error)?;
        for curve in &panel.curves {
            let (color, pattern) = line_style(curve.color);
            // The interquartile band: upper quartiles left to right, then lower quartiles back.
            let band: Vec<(f64, f64)> = curve
                .points
                .iter()
                .map(|p| (p.x, p.upper_quartile))
                .chain(curve.points.iter().rev().map(|p| (p.x, p.lower_quartile)))
                .collect();
            if curve.points.len() > 1 {
                chart
                    .draw_series(std::iter::once(Polygon::new(
                        band,
                        color.mix(0.18).filled(),
                    )))
                    .map_err(plot_error)?;
            }
            let medians = curve.points.iter().map(|p| (p.x, p.median));
            if let Some((dash, gap)) = pattern {
                chart
                    .draw_series(DashedLineSeries::new(
                        medians,
                        dash,
                        gap,
                        color.stroke_width(2),
                    ))
                    .map_err(plot_error)?;
            } else {
                chart
                    .draw_series(LineSeries::new(medians, color.stroke_width(2)))
                    .map_err(plot_error)?;
            }
        }
        if let Some(threshold) = panel.threshold {
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(x_min, threshold), (x_max, threshold)],
                    9,
                    6,
                    BLACK.stroke_width(1),
                ))
                .map_err(plot_error)?;
        }
    }
    draw_legend(&legend_area, layout)
}

/// One legend for the whole figure below the panels: rows of entries, each row centred.
fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, layout: &Layout) -> Result<()> {
    let style = TextStyle::from((FONT_FAMILY, LEGEND_FONT as f64).into_font())
        .pos(Pos::new(HPos::Left, VPos::Center));
    let (width, _) = area.dim_in_pixel();
    for (row_index, row) in layout.legend_rows.iter().enumerate() {
        let row_width: u32 = row
            .iter()
            .map(|e| e.width + ENTRY_SPACING)
            .sum::<u32>()
            .saturating_sub(ENTRY_SPACING);
        let mut x = (width.saturating_sub(row_width) / 2) as i32;
        let y =
            (LEGEND_PADDING + LEGEND_ROW_HEIGHT * row_index as u32 + LEGEND_ROW_HEIGHT / 2) as i32;
        let swatch = SWATCH as i32;
        for entry in row {
            match entry.color {
                Some(index) => {
                    let (color, pattern) = line_style(index);
                    area.draw(&Rectangle::new(
                        [(x, y - 7), (x + swatch, y + 7)],
                        color.mix(0.18).filled(),
                    ))
                    .map_err(plot_error)?;
                    let line = vec![(x, y), (x + swatch, y)];
                    if let Some((dash, gap)) = pattern {
                        area.draw(&DashedPathElement::new(
                            line,
                            dash,
                            gap,
                            color.stroke_width(3),
                        ))
                    } else {
                        area.draw(&PathElement::new(line, color.stroke_width(3)))
                    }
                    .map_err(plot_error)?;
                }
                None => {
                    area.draw(&DashedPathElement::new(
                        vec![(x, y), (x + swatch, y)],
                        9,
                        6,
                        BLACK.stroke_width(1),
                    ))
                    .map_err(plot_error)?;
                }
            }
            area.draw(&Text::new(
                entry.label.clone(),
                (x + swatch + SWATCH_GAP as i32, y),
                style.clone(),
            ))
            .map_err(plot_error)?;
            x += (entry.width + ENTRY_SPACING) as i32;
        }
    }
    Ok(())
}

/// Renders `figure` to `out_dir/NAME.png` and `out_dir/NAME.svg` (each written to a temporary file first and
/// renamed into place) and returns the two paths.
pub fn draw_figure(figure: &FigureContent, out_dir: &Path, name: &str) -> Result<Vec<PathBuf>> {
    ensure_font()?;
    let layout = layout(figure)?;
    let size = layout.size;
    let png_path = out_dir.join(format!("{name}.png"));
    // The bitmap backend picks the encoder from the extension, so the temporary name keeps `.png`.
    let png_tmp = out_dir.join(format!(".{name}.tmp{}.png", std::process::id()));
    {
        let root = BitMapBackend::new(&png_tmp, size).into_drawing_area();
        draw_on(&root, figure, &layout)?;
        root.present()
            .map_err(plot_error)
            .with_context(|| format!("cannot write {}", png_tmp.display()))?;
    }
    std::fs::rename(&png_tmp, &png_path)
        .with_context(|| format!("cannot write {}", png_path.display()))?;

    let svg_path = out_dir.join(format!("{name}.svg"));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_on(&root, figure, &layout)?;
        root.present().map_err(plot_error)?;
    }
    write_atomic(&svg_path, svg.as_bytes())?;
    Ok(vec![png_path, svg_path])
}

#[cfg(test)]
mod tests {

    #[test]
    fn axis_labels_keep_the_decimals_that_tell_ticks_apart() {
        // Returns from -500 to -80: whole numbers, as step counts are written.
        assert_eq!(format_axis(-250.0, 420.0), "-250");
        assert_eq!(format_axis(2500.0, 20000.0), "2.5k");
        // A normalised AUC from 0.85 to 1.05: ticks 0.03 apart need two decimals, not "1" for 0.95 and 1.0.
        assert_eq!(format_axis(0.95, 0.2), "0.95");
        assert_eq!(format_axis(1.0, 0.2), "1.00");
        assert_eq!(format_axis(0.5, 3.0), "0.5");
    }

    use super::*;

    #[test]
    fn budget_multiples_read_as_fractions_and_whole_numbers() {
        let scale = XScale::Log2Multiple;
        let labels: Vec<String> = [-2.0, -1.0, 0.0, 1.0, 2.0, 0.5]
            .iter()
            .map(|&x| scale.label(x))
            .collect();
        assert_eq!(labels, ["1/4", "1/2", "1", "2", "4", ""]);
        // Whole powers of two from 1/4 to 4 get a tick each, with a quarter step of room on either side.
        let (lo, hi) = scale.range(-2.0, 2.0);
        assert_eq!((lo, hi), (-2.25, 2.25));
        assert_eq!(scale.ticks(hi - lo), 5);
    }

    #[test]
    fn step_ticks_are_short() {
        assert_eq!(format_steps(500.0), "500");
        assert_eq!(format_steps(2500.0), "2.5k");
        assert_eq!(format_steps(200000.0), "200k");
        assert_eq!(format_steps(1.5e6), "1.5M");
        assert_eq!(format_steps(-120.0), "-120");
    }
}
