//! Figures: the paper's learning-curve figures (and a query timeline) drawn from run records, as PNG and SVG.
//!
//! The parts fit as follows:
//! - [`median_curve`] and [`query_timeline`] reduce the runs of one configuration to a [`Band`] per step: the
//!   median over seeds (the paper plots medians, docs/algorithm.md section 11) and the interquartile range.
//! - [`paper_figures`] selects runs for each figure of the paper's Section 4 and builds a [`FigureContent`]
//!   (one panel per environment, one line per method or setting), or says why a figure is skipped.
//! - [`draw_figure`] renders a figure with `plotters` to `NAME.png` and `NAME.svg`. Text is drawn with the
//!   DejaVu Sans font embedded in the binary (assets/), so no system font library is needed.

use super::protocol::{self, env_order};
use super::stats::quantile;
use crate::paper::TABLE5_METHODS;
use crate::train::run_dir::{DEFAULT_VARIANT, RunRecord, write_atomic};
use crate::train::{Method, NetKind};
use anyhow::{Context, Result, anyhow};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontStyle, register_font};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Once;

/// DejaVu Sans (Bitstream Vera license, see assets/DejaVuSans-LICENSE.txt).
static FONT_BYTES: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
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

/// One line of a panel with its interquartile band; `color` indexes [`PALETTE`].
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

/// A figure: a row (or grid) of panels sharing axis labels and one legend.
#[derive(Debug, Clone)]
pub struct FigureContent {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub panels: Vec<Panel>,
}

/// A figure of the paper: its file name stem and content, or why it is skipped.
#[derive(Debug, Clone)]
pub struct PaperFigure {
    pub name: String,
    pub content: Option<FigureContent>,
    pub skip_reason: String,
}

/// Line colours (Okabe-Ito, readable with colour-vision deficiencies); methods use the index of
/// [`TABLE5_METHODS`] so a method keeps its colour across figures.
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

fn method_color(method: Method) -> usize {
    TABLE5_METHODS
        .iter()
        .position(|m| *m == method.name())
        .unwrap_or(6)
}

/// Median and quartiles over the given values of each x, in x order.
fn bands(per_x: BTreeMap<u64, Vec<f64>>) -> Vec<Band> {
    per_x
        .into_iter()
        .filter_map(|(x, values)| {
            Some(Band {
                x: x as f64,
                median: quantile(&values, 0.5)?,
                lower_quartile: quantile(&values, 0.25)?,
                upper_quartile: quantile(&values, 0.75)?,
            })
        })
        .collect()
}

/// Median learning curve over runs (seeds): at each evaluation step, the median and quartiles of the seeds'
/// mean test returns. A step only some seeds reached is summarised over those seeds.
pub fn median_curve(runs: &[&RunRecord]) -> Vec<Band> {
    let mut per_step: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    for run in runs {
        for point in &run.eval {
            per_step.entry(point.step).or_default().push(point.mean);
        }
    }
    bands(per_step)
}

/// Queries per evaluation period over training, median over the runs that logged queries: bin k counts the
/// queries at steps in [k P, (k + 1) P) and is plotted at x = (k + 1) P, where P is the runs' evaluation period.
pub fn query_timeline(runs: &[&RunRecord]) -> Vec<Band> {
    let logged: Vec<(&RunRecord, &Vec<u64>)> = runs
        .iter()
        .filter_map(|r| r.query_steps.as_ref().map(|q| (*r, q)))
        .collect();
    let Some(period) = logged.iter().map(|(r, _)| r.eval_period).max() else {
        return Vec::new();
    };
    let steps = logged.iter().map(|(r, _)| r.train_steps).max().unwrap_or(0);
    let bins = steps.div_ceil(period).max(1) as usize;
    let mut per_bin: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    for (_, queries) in &logged {
        let mut counts = vec![0.0; bins];
        for &step in queries.iter() {
            let bin = ((step / period) as usize).min(bins - 1);
            counts[bin] += 1.0;
        }
        for (k, count) in counts.into_iter().enumerate() {
            per_bin
                .entry((k as u64 + 1) * period)
                .or_default()
                .push(count);
        }
    }
    bands(per_bin)
}

/// Readable legend text for an expert spec of the expert-quality study.
fn expert_label(spec: &str) -> String {
    match spec {
        "shipped:perfect" => "perfect expert".to_string(),
        "shipped:weak" => "weak (snapshot) expert".to_string(),
        other => match other
            .strip_prefix("noisy:")
            .and_then(|rest| rest.split_once(':'))
        {
            Some((p, inner)) if p.parse::<f64>().is_ok() => {
                format!(
                    "{} + {}% random actions",
                    expert_label(inner),
                    (p.parse::<f64>().unwrap_or(0.0) * 100.0).round()
                )
            }
            _ => other.to_string(),
        },
    }
}

fn net_words(net: NetKind) -> (&'static str, &'static str) {
    match net {
        NetKind::Bootstrap => ("bootstrapped", "B"),
        NetKind::Noisy => ("noisy", "N"),
        NetKind::Plain => ("plain", "P"),
    }
}

const RETURN_LABEL: &str = "mean test return (20 episodes)";
const STEPS_LABEL: &str = "environment steps";

/// Panels per environment, one curve per method, for the default-variant runs of `methods` on `net`.
fn methods_figure(
    runs: &[RunRecord],
    net: NetKind,
    methods: &[Method],
    title: String,
) -> Option<FigureContent> {
    let selected: Vec<&RunRecord> = runs
        .iter()
        .filter(|r| r.net == net && r.variant == DEFAULT_VARIANT && methods.contains(&r.method))
        .collect();
    let envs = env_order(selected.iter().map(|r| r.env.as_str()));
    let panels: Vec<Panel> = envs
        .iter()
        .map(|env| {
            let in_env: Vec<&RunRecord> =
                selected.iter().copied().filter(|r| &r.env == env).collect();
            let curves = methods
                .iter()
                .filter_map(|method| {
                    let group: Vec<&RunRecord> = in_env
                        .iter()
                        .copied()
                        .filter(|r| r.method == *method)
                        .collect();
                    (!group.is_empty()).then(|| Curve {
                        label: method.paper_name(),
                        color: method_color(*method),
                        points: median_curve(&group),
                    })
                })
                .collect();
            Panel {
                title: env.clone(),
                threshold: in_env.first().map(|r| r.solve_threshold),
                curves,
            }
        })
        .collect();
    (!panels.is_empty()).then(|| FigureContent {
        title,
        x_label: STEPS_LABEL.to_string(),
        y_label: RETURN_LABEL.to_string(),
        panels,
    })
}

/// ADQN runs of the t_query study (variant `tqVALUE`): panels per environment, one curve per value.
fn t_query_figure(runs: &[RunRecord], net: NetKind) -> Option<FigureContent> {
    let selected: Vec<(&RunRecord, f64)> = runs
        .iter()
        .filter(|r| r.net == net && r.method == Method::Adqn)
        .filter_map(|r| Some((r, r.variant.strip_prefix("tq")?.parse::<f64>().ok()?)))
        .collect();
    let mut values: Vec<f64> = selected.iter().map(|(_, t)| *t).collect();
    values.sort_by(f64::total_cmp);
    values.dedup();
    let envs = env_order(selected.iter().map(|(r, _)| r.env.as_str()));
    let panels: Vec<Panel> = envs
        .iter()
        .map(|env| {
            let in_env: Vec<&(&RunRecord, f64)> =
                selected.iter().filter(|(r, _)| &r.env == env).collect();
            let curves = values
                .iter()
                .enumerate()
                .filter_map(|(i, value)| {
                    let group: Vec<&RunRecord> = in_env
                        .iter()
                        .filter(|(_, t)| t == value)
                        .map(|(r, _)| *r)
                        .collect();
                    (!group.is_empty()).then(|| Curve {
                        label: format!("t_query = {value}"),
                        color: [4, 3, 5, 1, 6, 2, 0, 7][i % PALETTE.len()],
                        points: median_curve(&group),
                    })
                })
                .collect();
            Panel {
                title: env.clone(),
                threshold: in_env.first().map(|(r, _)| r.solve_threshold),
                curves,
            }
        })
        .collect();
    let (words, suffix) = net_words(net);
    (!panels.is_empty()).then(|| FigureContent {
        title: format!("ADQN-{suffix} with t_query in {{0.05, 0.1, 0.3, 0.5}} ({words} DQN)"),
        x_label: STEPS_LABEL.to_string(),
        y_label: RETURN_LABEL.to_string(),
        panels,
    })
}

/// ADQN and DQfD runs of the expert-quality study (variant `expert-...`): a panel per (environment, method),
/// one curve per expert.
fn expert_figure(runs: &[RunRecord], net: NetKind) -> Option<FigureContent> {
    let selected: Vec<&RunRecord> = runs
        .iter()
        .filter(|r| r.net == net && (r.method == Method::Adqn || r.method == Method::Dqfd))
        .filter(|r| r.variant.starts_with("expert-") && !r.variant.contains('_'))
        .collect();
    // Legend order and colours follow the paper's order of experts; unknown specs come after, alphabetically.
    let mut experts: Vec<String> = selected
        .iter()
        .map(|r| r.expert.clone().unwrap_or_else(|| r.variant.clone()))
        .collect();
    experts.sort_by_key(|e| {
        (
            protocol::EXPERT_QUALITY_SPECS
                .iter()
                .position(|s| s == e)
                .unwrap_or(usize::MAX),
            e.clone(),
        )
    });
    experts.dedup();
    let envs = env_order(selected.iter().map(|r| r.env.as_str()));
    let mut panels = Vec::new();
    for env in &envs {
        for method in [Method::Adqn, Method::Dqfd] {
            let in_panel: Vec<&RunRecord> = selected
                .iter()
                .copied()
                .filter(|r| &r.env == env && r.method == method)
                .collect();
            if in_panel.is_empty() {
                continue;
            }
            let curves = experts
                .iter()
                .enumerate()
                .filter_map(|(i, expert)| {
                    let group: Vec<&RunRecord> = in_panel
                        .iter()
                        .copied()
                        .filter(|r| r.expert.as_ref().unwrap_or(&r.variant) == expert)
                        .collect();
                    (!group.is_empty()).then(|| Curve {
                        label: expert_label(expert),
                        color: [4, 1, 3, 5, 6, 2, 0, 7][i % PALETTE.len()],
                        points: median_curve(&group),
                    })
                })
                .collect();
            let (_, suffix) = net_words(net);
            panels.push(Panel {
                title: format!("{env}: {}-{suffix}", method.paper_name()),
                threshold: in_panel.first().map(|r| r.solve_threshold),
                curves,
            });
        }
    }
    let (words, suffix) = net_words(net);
    (!panels.is_empty()).then(|| FigureContent {
        title: format!(
            "Effect of the expert's quality on ADQN-{suffix} and DQfD-{suffix} ({words} DQN)"
        ),
        x_label: STEPS_LABEL.to_string(),
        y_label: RETURN_LABEL.to_string(),
        panels,
    })
}

/// Queries per evaluation period for the querying methods (default variant), one panel per environment.
fn query_figure(runs: &[RunRecord], net: NetKind) -> Option<FigureContent> {
    let methods = [Method::Gdqn, Method::Bdqn, Method::Adqn, Method::Adqnp];
    let selected: Vec<&RunRecord> = runs
        .iter()
        .filter(|r| r.net == net && r.variant == DEFAULT_VARIANT && methods.contains(&r.method))
        .filter(|r| r.query_steps.is_some())
        .collect();
    let envs = env_order(selected.iter().map(|r| r.env.as_str()));
    let panels: Vec<Panel> = envs
        .iter()
        .map(|env| {
            let curves = methods
                .iter()
                .filter_map(|method| {
                    let group: Vec<&RunRecord> = selected
                        .iter()
                        .copied()
                        .filter(|r| &r.env == env && r.method == *method)
                        .collect();
                    (!group.is_empty()).then(|| Curve {
                        label: method.paper_name(),
                        color: method_color(*method),
                        points: query_timeline(&group),
                    })
                })
                .collect();
            Panel {
                title: env.clone(),
                threshold: None,
                curves,
            }
        })
        .collect();
    let (words, suffix) = net_words(net);
    (!panels.is_empty()).then(|| FigureContent {
        title: format!("When the agent asks: queries over training (-{suffix}, {words} DQN)"),
        x_label: STEPS_LABEL.to_string(),
        y_label: "queries per evaluation period".to_string(),
        panels,
    })
}

/// The paper's figures built from `runs`, in the paper's order, each for bootstrapped and noisy nets:
/// `fig1_methods_*` (DQN, GDQN, BDQN, ADQN), `fig2_pretraining_*` (DQfD, ADQN, ADQNP), `fig3_t_query_*`,
/// `fig4_experts_*`, and `fig5_queries_*` (a query timeline, not in the paper).
pub fn paper_figures(runs: &[RunRecord]) -> Vec<PaperFigure> {
    let mut figures = Vec::new();
    for net in [NetKind::Bootstrap, NetKind::Noisy] {
        let (words, suffix) = net_words(net);
        let mut push = |name: String, content: Option<FigureContent>, missing: String| {
            let skip_reason = if content.is_some() {
                String::new()
            } else {
                missing
            };
            figures.push(PaperFigure {
                name,
                content,
                skip_reason,
            });
        };
        push(
            format!("fig1_methods_{net}"),
            methods_figure(
                runs,
                net,
                &[Method::Dqn, Method::Gdqn, Method::Bdqn, Method::Adqn],
                format!("Comparison between methods with {words} DQN (-{suffix})"),
            ),
            format!("no complete default-variant run of DQN, GDQN, BDQN or ADQN with net = {net}"),
        );
        push(
            format!("fig2_pretraining_{net}"),
            methods_figure(
                runs,
                net,
                &[Method::Dqfd, Method::Adqn, Method::Adqnp],
                format!("ADQN, DQfD and ADQNP based on {words} DQN (-{suffix})"),
            ),
            format!("no complete default-variant run of DQfD, ADQN or ADQNP with net = {net}"),
        );
        push(
            format!("fig3_t_query_{net}"),
            t_query_figure(runs, net),
            format!("no complete ADQN run of a t_query sweep (variant tqVALUE) with net = {net}"),
        );
        push(
            format!("fig4_experts_{net}"),
            expert_figure(runs, net),
            format!(
                "no complete ADQN or DQfD run of an expert sweep (variant expert-...) with net = {net}"
            ),
        );
        push(
            format!("fig5_queries_{net}"),
            query_figure(runs, net),
            format!(
                "no complete default-variant run of a querying method with a queries.csv and net = {net}"
            ),
        );
    }
    figures.sort_by(|a, b| a.name.cmp(&b.name));
    figures
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

/// Axis ranges of a panel: x from 0 to the last step, y covering bands and threshold with 5% padding.
fn panel_ranges(panel: &Panel) -> (f64, (f64, f64)) {
    let points = panel.curves.iter().flat_map(|c| c.points.iter());
    let x_max = points.clone().map(|p| p.x).fold(0.0, f64::max);
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
    (
        if x_max > 0.0 { x_max } else { 1.0 },
        (y_min - pad, y_max + pad),
    )
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
        let (x_max, (y_min, y_max)) = panel_ranges(panel);
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, (FONT_FAMILY, 19))
            .margin_top(6)
            .margin_left(8)
            .margin_right(22)
            .margin_bottom(6)
            .x_label_area_size(52)
            .y_label_area_size(74)
            .build_cartesian_2d(0.0..x_max, y_min..y_max)
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .x_desc(figure.x_label.as_str())
            .y_desc(figure.y_label.as_str())
            .x_labels(6)
            .y_labels(7)
            .x_label_formatter(&|x| format_steps(*x))
            .y_label_formatter(&|y| format_steps(*y))
            .label_style((FONT_FAMILY, 14))
            .axis_desc_style((FONT_FAMILY, 16))
            .bold_line_style(RGBColor(225, 225, 225))
            .light_line_style(RGBColor(245, 245, 245))
            .draw()
            .map_err(plot_error)?;
        for curve in &panel.curves {
            let color = PALETTE[curve.color % PALETTE.len()];
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
            chart
                .draw_series(LineSeries::new(
                    curve.points.iter().map(|p| (p.x, p.median)),
                    color.stroke_width(2),
                ))
                .map_err(plot_error)?;
        }
        if let Some(threshold) = panel.threshold {
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(0.0, threshold), (x_max, threshold)],
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
                    let color = PALETTE[index % PALETTE.len()];
                    area.draw(&Rectangle::new(
                        [(x, y - 7), (x + swatch, y + 7)],
                        color.mix(0.18).filled(),
                    ))
                    .map_err(plot_error)?;
                    area.draw(&PathElement::new(
                        vec![(x, y), (x + swatch, y)],
                        color.stroke_width(3),
                    ))
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
    use super::*;
    use crate::train::run_dir::EvalPoint;

    fn run(seed: u64, means: &[f64], queries: Option<Vec<u64>>) -> RunRecord {
        RunRecord {
            dir: PathBuf::from(format!("seed{seed}")),
            env: "CartPole-v0".into(),
            method: Method::Adqn,
            net: NetKind::Bootstrap,
            seed,
            variant: DEFAULT_VARIANT.into(),
            t_query: None,
            expert: None,
            solve_threshold: 195.0,
            train_steps: 3000,
            eval_period: 1000,
            eval: means
                .iter()
                .enumerate()
                .map(|(i, &mean)| EvalPoint::constant((i as u64 + 1) * 1000, mean))
                .collect(),
            query_steps: queries,
            summary_steps_to_solve: None,
        }
    }

    #[test]
    fn median_curve_takes_per_step_median_and_quartiles_over_seeds() {
        let runs = [
            run(0, &[10.0, 100.0], None),
            run(1, &[30.0, 200.0], None),
            run(2, &[20.0, 150.0], None),
        ];
        let refs: Vec<&RunRecord> = runs.iter().collect();
        let curve = median_curve(&refs);
        assert_eq!(curve.len(), 2);
        assert_eq!(
            (
                curve[0].x,
                curve[0].median,
                curve[0].lower_quartile,
                curve[0].upper_quartile
            ),
            (1000.0, 20.0, 15.0, 25.0)
        );
        assert_eq!(curve[1].median, 150.0);
    }

    #[test]
    fn query_timeline_counts_queries_per_evaluation_period() {
        let runs = [
            run(0, &[], Some(vec![0, 5, 999, 1000, 2999])),
            run(1, &[], Some(vec![10, 20, 30])),
            run(2, &[], None),
        ];
        let refs: Vec<&RunRecord> = runs.iter().collect();
        let timeline = query_timeline(&refs);
        let medians: Vec<(f64, f64)> = timeline.iter().map(|b| (b.x, b.median)).collect();
        // Seed 0 bins: [3, 1, 1]; seed 1: [3, 0, 0]; seed 2 logged nothing and is left out.
        assert_eq!(medians, vec![(1000.0, 3.0), (2000.0, 0.5), (3000.0, 0.5)]);
    }

    #[test]
    fn step_ticks_are_short() {
        assert_eq!(format_steps(500.0), "500");
        assert_eq!(format_steps(2500.0), "2.5k");
        assert_eq!(format_steps(200000.0), "200k");
        assert_eq!(format_steps(1.5e6), "1.5M");
        assert_eq!(format_steps(-120.0), "-120");
    }

    #[test]
    fn expert_labels_are_readable() {
        assert_eq!(
            expert_label("noisy:0.4:shipped:perfect"),
            "perfect expert + 40% random actions"
        );
        assert_eq!(expert_label("file:x.safetensors"), "file:x.safetensors");
    }
}
