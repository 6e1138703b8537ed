//! Figures of histograms a person can read without the CSV: axes in data
//! units with ticks and labels, a title naming the input, and for 2D
//! histograms a colour bar of the counts.
//!
//! Drawn with `plotters` and the DejaVu Sans font bundled in the binary, so
//! no system font is needed. A 2D histogram is shown as a heat map (empty
//! bins white, others on a viridis-like ramp of [`grey_level`]'s scaled
//! count), sampled at the plot's pixels (at most [`PLOT_PIXELS`] per axis:
//! finer histograms are shown by their nearest bin; the NRRD and EXR files
//! keep every bin). A 1D histogram is drawn as the two overlaid bar scales
//! of [`Histogram::image`] (log grey behind linear black), each against its
//! own labelled axis.

use crate::count::Histogram;
use crate::image::{Scale, grey_level};
use crate::rgb::{GAP, Rgb};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Largest side of the plotting area, pixels.
pub const PLOT_PIXELS: u32 = 512;
/// Figure size, pixels (the plot, its axes, title and colour bar).
pub const FIGURE_SIZE: (u32, u32) = (780, 620);

/// What the figure says: its title (e.g. the input's name), a label with
/// units per axis, a note below the plot (e.g. how an axis was clipped) and
/// the boundaries to draw on a (v, g) plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Labels {
    /// Title above the plot.
    pub title: String,
    /// One label per histogram axis, with units.
    pub axes: Vec<String>,
    /// A line of small text below the plot.
    pub note: Option<String>,
    /// Boundaries drawn as their model arches (2D figures over (v, g) only).
    pub arches: Vec<ArchMark>,
}

/// A boundary drawn on a (v, g) figure as the arch an ideal blurred step
/// from `v_low` to `v_high` with peak gradient `g_peak` draws: g = G
/// exp(-t^2 / 2) at v = v_low + (v_high - v_low) Phi(t), labelled at its apex.
#[derive(Debug, Clone, PartialEq)]
pub struct ArchMark {
    /// Value of the material on the low side (input units).
    pub v_low: f64,
    /// Value of the material on the high side.
    pub v_high: f64,
    /// Peak gradient magnitude, at the apex (input units per world unit).
    pub g_peak: f64,
    /// Short label at the apex (e.g. the boundary's number).
    pub label: String,
    /// Line and label colour.
    pub colour: [u8; 3],
    /// Drawn as the line the boundary collapses to in a stretched (v, g_hit)
    /// histogram, g = `g_peak` over the arch's v span, instead of the arch.
    pub collapsed: bool,
}

impl ArchMark {
    /// The same boundary drawn where a stretched (v, g_hit) histogram gathers it.
    pub fn collapsed(&self) -> ArchMark {
        ArchMark { collapsed: true, ..self.clone() }
    }
}

/// An RGBA table over a 2D figure's two axes (e.g. a transfer function
/// over (v, g)), drawn over the counts: each pixel mixes the table's colour
/// in by the square root of its opacity relative to the table's largest,
/// so that faint widgets still show; the counts are then drawn in greys on
/// black so that white and coloured widgets both stand out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Overlay<'a> {
    /// Lower and upper edge and cells of the table along the figure's first axis (its units).
    pub x: (f64, f64, usize),
    /// The same along the second axis.
    pub y: (f64, f64, usize),
    /// RGBA per cell, first axis fastest; colour in [0, 1], opacity at least 0.
    pub rgba: &'a [f32],
}

impl Overlay<'_> {
    /// The largest opacity of the table (0 when it is empty).
    fn max_alpha(&self) -> f32 {
        self.rgba.chunks_exact(4).map(|c| c[3]).fold(0.0, f32::max)
    }

    /// RGBA of the cell holding (x, y), None outside the table.
    fn at(&self, x: f64, y: f64) -> Option<&[f32]> {
        let cell = |v: f64, (lo, hi, n): (f64, f64, usize)| {
            let t = (v - lo) / (hi - lo);
            (0.0..1.0).contains(&t).then(|| ((t * n as f64) as usize).min(n - 1))
        };
        let (i, j) = (cell(x, self.x)?, cell(y, self.y)?);
        self.rgba.get(4 * (j * self.x.2 + i)..4 * (j * self.x.2 + i) + 4)
    }
}

/// A channel's quantity and its generic unit (when the input states none),
/// for the axes of histogram figures.
fn quantity_and_unit(name: &str) -> (&str, &str) {
    match name {
        "v" => ("v", "input units"),
        "g" => ("g = |grad v|", "input units per world unit"),
        "f2" => ("f'' along the gradient", "input units per world unit^2"),
        "inv_g" => ("1/g", "world units per input unit; of several fields 1/sqrt(||G||), world units"),
        "g_hit" => ("g at the boundary hit", "input units per world unit"),
        "distance" => ("distance to the boundary", "world units"),
        "gnorm" => ("||G||", "per world unit^2"),
        other => (other, "field units"),
    }
}

/// The label of `axis` for histogram figures: its channel's quantity with
/// the axis's unit when the input stated one (e.g. "v (HU)", "g = |grad v|
/// (HU/mm)"), else [`axis_label`]'s generic units.
pub fn axis_label_of(axis: &crate::Axis) -> String {
    let (quantity, generic) = quantity_and_unit(&axis.name);
    format!("{quantity} ({})", axis.unit.as_deref().unwrap_or(generic))
}

/// The label of channel `name` with its generic units, for the axes of histogram figures.
pub fn axis_label(name: &str) -> String {
    let (quantity, unit) = quantity_and_unit(name);
    format!("{quantity} ({unit})")
}

impl Labels {
    /// Labels for `h` titled `title`, each axis labelled by [`axis_label_of`].
    pub fn of(h: &Histogram, title: &str) -> Labels {
        Labels { title: title.into(), axes: h.axes.iter().map(axis_label_of).collect(), note: None, arches: Vec::new() }
    }
}

/// The grey of count `c` under an [`Overlay`]: black for 0, else 40..200 by the scaled count.
fn dark_count_colour(c: u64, max: u64, scale: Scale) -> [u8; 3] {
    if c == 0 {
        return [0, 0, 0];
    }
    let l = (40.0 + 160.0 * grey_level(c, max, scale) as f64 / 255.0).round() as u8;
    [l, l, l]
}

/// How count colours are chosen: [`count_colour`] or, under an overlay, [`dark_count_colour`].
type CountPalette = fn(u64, u64, Scale) -> [u8; 3];

/// A viridis-like ramp at t in [0, 1] (five anchors, linear between).
fn ramp(t: f64) -> [u8; 3] {
    const ANCHORS: [[f64; 3]; 5] =
        [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];
    let x = t.clamp(0.0, 1.0) * 4.0;
    let k = (x.floor() as usize).min(3);
    let f = x - k as f64;
    [0, 1, 2].map(|c| (ANCHORS[k][c] + f * (ANCHORS[k + 1][c] - ANCHORS[k][c])).round() as u8)
}

/// The colour of count `c` with the largest count `max`: white for 0, else the ramp.
pub fn count_colour(c: u64, max: u64, scale: Scale) -> [u8; 3] {
    if c == 0 { [255, 255, 255] } else { ramp(grey_level(c, max, scale) as f64 / 255.0) }
}

/// Errors of plotting, as text (plotters' own error type is generic over the backend).
fn plot_err<E: std::fmt::Debug>(e: E) -> String {
    format!("drawing the figure: {e:?}")
}

/// Width of the colour bar's area at the right of a 2D figure, pixels.
const COLOUR_BAR_WIDTH: u32 = 130;
/// Size of a figure of two 2D histograms side by side, pixels.
pub const SIDE_BY_SIDE_SIZE: (u32, u32) = (1180, 560);

/// Pixel ranges (x, y) of a plot on the bitmap.
type PixelRect = (std::ops::Range<i32>, std::ops::Range<i32>);

/// Draws the title and the labelled axes of `h`'s heat map in `area`;
/// returns the plot's pixels, which [`fill_heat_map`] then fills.
fn heat_map_axes(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    h: &Histogram,
    labels: &Labels,
) -> Result<PixelRect, String> {
    let mut chart = heat_map_chart(area, h, labels)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(labels.axes.first().map_or("", String::as_str))
        .y_desc(labels.axes.get(1).map_or("", String::as_str))
        .axis_desc_style(("sans-serif", 14))
        .label_style(("sans-serif", 12))
        .draw()
        .map_err(plot_err)?;
    Ok(chart.plotting_area().get_pixel_range())
}

type HeatMapChart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// The caption's font size, px: 18, or smaller (down to 11) when `title`
/// would not fit the width of `area` (a long input name centred past the
/// picture's edges loses its ends).
fn caption_size(area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>, title: &str) -> u32 {
    let room = area.dim_in_pixel().0.saturating_sub(2 * 12);
    let fits = |size: u32| {
        let font = TextStyle::from(("sans-serif", size).into_font());
        area.estimate_text_size(title, &font).is_ok_and(|(w, _)| w <= room)
    };
    (11..=18).rev().find(|&size| fits(size)).unwrap_or(11)
}

/// The chart of `h`'s heat map in `area` (title, margins, label areas): the
/// same layout each time it is built, so marks drawn on a second build
/// land on the first one's axes.
fn heat_map_chart<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    h: &Histogram,
    labels: &Labels,
) -> Result<HeatMapChart<'a, 'b>, String> {
    let (ax, ay) = (&h.axes[0], &h.axes[1]);
    ChartBuilder::on(area)
        .caption(&labels.title, ("sans-serif", caption_size(area, &labels.title)))
        .margin(12)
        .margin_bottom(12 + note_height(labels))
        .x_label_area_size(AXIS_LABEL_AREA)
        .y_label_area_size(70)
        .build_cartesian_2d(ax.min..ax.max, ay.min..ay.max)
        .map_err(plot_err)
}

/// Draws `labels`' arches and note over a filled heat map in `area`.
fn draw_marks(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    h: &Histogram,
    labels: &Labels,
) -> Result<(), String> {
    let mut chart = heat_map_chart(area, h, labels)?;
    let (ax, ay) = (&h.axes[0], &h.axes[1]);
    let inside = |v: f64, g: f64| v >= ax.min && v <= ax.max && g >= ay.min && g <= ay.max;
    for a in &labels.arches {
        let colour = RGBColor(a.colour[0], a.colour[1], a.colour[2]);
        let arch = (0..=80).map(|k| {
            let t = -3.0 + 6.0 * k as f64 / 80.0;
            let phi = 0.5 * (1.0 + libm::erf(t / std::f64::consts::SQRT_2));
            let g = if a.collapsed { a.g_peak } else { a.g_peak * (-0.5 * t * t).exp() };
            (a.v_low + (a.v_high - a.v_low) * phi, g)
        });
        let arch: Vec<(f64, f64)> = arch.filter(|&(v, g)| inside(v, g)).collect();
        // a dark edge under the colour, so that any colour shows on light and dark plots
        chart.draw_series(LineSeries::new(arch.iter().copied(), BLACK.stroke_width(4))).map_err(plot_err)?;
        chart.draw_series(LineSeries::new(arch, colour.stroke_width(2))).map_err(plot_err)?;
        let centre = 0.5 * (a.v_low + a.v_high);
        if inside(centre, a.g_peak) {
            let at = chart.backend_coord(&(centre, a.g_peak));
            let font = ("sans-serif", 18).into_font();
            let anchor = Pos::new(HPos::Center, VPos::Bottom);
            for (dx, dy, c) in [(1, 1, BLACK), (-1, -1, BLACK), (0, 0, colour)] {
                area.draw_text(&a.label, &font.color(&c).pos(anchor), (at.0 + dx, at.1 - 4 + dy)).map_err(plot_err)?;
            }
        }
    }
    if let Some(note) = &labels.note {
        let (_, height) = area.dim_in_pixel();
        area.draw_text(note, &("sans-serif", 12).into_font().color(&RGBColor(60, 60, 60)), (8, height as i32 - 22))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// Height of the tick labels and axis label below a heat map, pixels.
const AXIS_LABEL_AREA: u32 = 48;

/// Height of the line of the note below the axis label (0 without a note), pixels.
fn note_height(labels: &Labels) -> u32 {
    if labels.note.is_some() { 20 } else { 0 }
}

/// Draws the log count axis of a colour bar for counts up to `max` in
/// `area`; returns the bar's pixels, which [`fill_colour_bar`] then fills.
fn colour_bar_axes(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    max: u64,
    scale: Scale,
    below: u32,
) -> Result<PixelRect, String> {
    let top = max.max(1) as f64;
    let mut bar = ChartBuilder::on(area)
        .margin_top(12 + 30)
        .margin_bottom(12 + below)
        .margin_right(12)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..1.0, (1.0..top.max(1.5)).log_scale())
        .map_err(plot_err)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(format!("voxels per bin ({scale:?} colours)"))
        .y_label_formatter(&|c| format!("{}", c.round() as u64))
        .axis_desc_style(("sans-serif", 12))
        .label_style(("sans-serif", 11))
        .draw()
        .map_err(plot_err)?;
    Ok(bar.plotting_area().get_pixel_range())
}

/// Calls `paint(x, y, i, j, tx, ty)` for every pixel (x, y) of the plot
/// `rect`, with the cell (i, j) of an `nx` x `ny` grid under the pixel's
/// centre (first axis right, second up) and that centre's position (tx, ty)
/// in [0, 1] along each axis.
fn each_plot_pixel(
    (px, py): &PixelRect,
    (nx, ny): (usize, usize),
    mut paint: impl FnMut(usize, usize, usize, usize, f64, f64),
) {
    let (pw, ph) = ((px.end - px.start).max(1) as f64, (py.end - py.start).max(1) as f64);
    for y in py.clone() {
        let ty = ((py.end - 1 - y) as f64 + 0.5) / ph;
        let j = ((ty * ny as f64) as usize).min(ny - 1);
        for x in px.clone() {
            let tx = ((x - px.start) as f64 + 0.5) / pw;
            let i = ((tx * nx as f64) as usize).min(nx - 1);
            paint(x as usize, y as usize, i, j, tx, ty);
        }
    }
}

/// Fills the plot `rect` of an RGB bitmap `width` pixels wide with `h`'s
/// heat map: each pixel shows the bin under its centre (first axis right, second up).
/// Under an `overlay`, the counts are dark greys and the table's colours are mixed in.
fn fill_heat_map(
    pixels: &mut [u8],
    width: usize,
    rect: PixelRect,
    h: &Histogram,
    (max, scale): (u64, Scale),
    overlay: Option<&Overlay>,
) {
    let (ax, ay) = (&h.axes[0], &h.axes[1]);
    let palette: CountPalette = if overlay.is_some() { dark_count_colour } else { count_colour };
    let alpha_max = overlay.map_or(0.0, |o| o.max_alpha());
    each_plot_pixel(&rect, (ax.bins, ay.bins), |x, y, i, j, tx, ty| {
        let mut rgb = palette(h.counts[j * ax.bins + i], max, scale);
        if let Some(cell) = overlay.and_then(|o| o.at(ax.min + tx * (ax.max - ax.min), ay.min + ty * (ay.max - ay.min)))
            && alpha_max > 0.0
        {
            let mix = (cell[3] / alpha_max).clamp(0.0, 1.0).sqrt();
            for k in 0..3 {
                let tf = 255.0 * cell[k].clamp(0.0, 1.0);
                rgb[k] = (rgb[k] as f32 * (1.0 - mix) + tf * mix).round() as u8;
            }
        }
        let o = 3 * (y * width + x);
        pixels[o..o + 3].copy_from_slice(&rgb);
    });
}

/// Fills the colour bar `rect`: at each height, the colour of the count the log axis beside it reads there.
fn fill_colour_bar(
    pixels: &mut [u8],
    width: usize,
    (bx, by): PixelRect,
    max: u64,
    scale: Scale,
    palette: CountPalette,
) {
    let bh = (by.end - by.start).max(1) as f64;
    for y in by.clone() {
        let t = ((by.end - 1 - y) as f64 + 0.5) / bh;
        let count = (max.max(1) as f64).powf(t).round() as u64;
        let colour = palette(count.max(1), max.max(1), scale);
        for x in bx.clone() {
            let o = 3 * (y as usize * width + x as usize);
            pixels[o..o + 3].copy_from_slice(&colour);
        }
    }
}

impl Histogram {
    /// The figure of a 1D or 2D histogram (None for 3D: see
    /// [`Histogram::rgb_projections`]), [`FIGURE_SIZE`] pixels.
    pub fn figure(&self, scale: Scale, labels: &Labels) -> Result<Option<Rgb>, String> {
        self.figure_with(scale, labels, None)
    }

    /// [`Histogram::figure`] with an RGBA table drawn over a 2D histogram's counts.
    pub fn figure_with(&self, scale: Scale, labels: &Labels, overlay: Option<&Overlay>) -> Result<Option<Rgb>, String> {
        mdtf_volume::register_figure_font();
        let (w, h) = FIGURE_SIZE;
        let mut pixels = vec![255u8; (w * h * 3) as usize];
        let drawn = match self.axes.len() {
            2 => self.draw_2d(&mut pixels, scale, labels, overlay)?,
            1 => self.draw_1d(&mut pixels, labels)?,
            _ => return Ok(None),
        };
        Ok(drawn.then_some(Rgb { width: w as usize, height: h as usize, pixels }))
    }

    fn draw_2d(
        &self,
        pixels: &mut [u8],
        scale: Scale,
        labels: &Labels,
        overlay: Option<&Overlay>,
    ) -> Result<bool, String> {
        let (w, h) = FIGURE_SIZE;
        let max = self.max();
        let (plot, bar);
        {
            let root = BitMapBackend::with_buffer(pixels, (w, h)).into_drawing_area();
            let (main, bar_area) = root.split_horizontally(w - COLOUR_BAR_WIDTH);
            plot = heat_map_axes(&main, self, labels)?;
            bar = colour_bar_axes(&bar_area, max, scale, AXIS_LABEL_AREA + note_height(labels))?;
            root.present().map_err(plot_err)?;
        }
        fill_heat_map(pixels, w as usize, plot, self, (max, scale), overlay);
        let palette: CountPalette = if overlay.is_some() { dark_count_colour } else { count_colour };
        fill_colour_bar(pixels, w as usize, bar, max, scale, palette);
        if !labels.arches.is_empty() || labels.note.is_some() {
            let root = BitMapBackend::with_buffer(pixels, (w, h)).into_drawing_area();
            let (main, _) = root.split_horizontally(w - COLOUR_BAR_WIDTH);
            draw_marks(&main, self, labels)?;
            root.present().map_err(plot_err)?;
        }
        Ok(true)
    }

    /// Two 2D histograms side by side over their own axes, sharing one
    /// colour scale (the larger of their largest counts) and its bar: e.g.
    /// the distance paper's normal | stretched (v, g_hit) figure.
    /// [`SIDE_BY_SIDE_SIZE`] pixels; None unless both are 2D.
    pub fn figure_beside(&self, other: &Histogram, scale: Scale, labels: [&Labels; 2]) -> Result<Option<Rgb>, String> {
        if self.axes.len() != 2 || other.axes.len() != 2 {
            return Ok(None);
        }
        mdtf_volume::register_figure_font();
        let (w, h) = SIDE_BY_SIDE_SIZE;
        let mut pixels = vec![255u8; (w * h * 3) as usize];
        let max = self.max().max(other.max());
        let (plots, bar);
        {
            let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
            let (panels, bar_area) = root.split_horizontally(w - COLOUR_BAR_WIDTH);
            let (left, right) = panels.split_horizontally((w - COLOUR_BAR_WIDTH) / 2);
            plots = [heat_map_axes(&left, self, labels[0])?, heat_map_axes(&right, other, labels[1])?];
            bar = colour_bar_axes(&bar_area, max, scale, AXIS_LABEL_AREA + note_height(labels[0]))?;
            root.present().map_err(plot_err)?;
        }
        let [p0, p1] = plots;
        fill_heat_map(&mut pixels, w as usize, p0, self, (max, scale), None);
        fill_heat_map(&mut pixels, w as usize, p1, other, (max, scale), None);
        fill_colour_bar(&mut pixels, w as usize, bar, max, scale, count_colour);
        if labels.iter().any(|l| !l.arches.is_empty() || l.note.is_some()) {
            let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
            let (panels, _) = root.split_horizontally(w - COLOUR_BAR_WIDTH);
            let (left, right) = panels.split_horizontally((w - COLOUR_BAR_WIDTH) / 2);
            draw_marks(&left, self, labels[0])?;
            draw_marks(&right, other, labels[1])?;
            root.present().map_err(plot_err)?;
        }
        Ok(Some(Rgb { width: w as usize, height: h as usize, pixels }))
    }

    fn draw_1d(&self, pixels: &mut [u8], labels: &Labels) -> Result<bool, String> {
        let (w, h) = FIGURE_SIZE;
        let a = &self.axes[0];
        let max = self.max().max(1) as f64;
        let root = BitMapBackend::with_buffer(pixels, (w, h)).into_drawing_area();
        let mut chart = ChartBuilder::on(&root)
            .caption(&labels.title, ("sans-serif", caption_size(&root, &labels.title)))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(70)
            .right_y_label_area_size(70)
            .build_cartesian_2d(a.min..a.max, 0.0..max * 1.05)
            .map_err(plot_err)?
            .set_secondary_coord(a.min..a.max, (1.0..max * 1.5).log_scale());
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(labels.axes.first().map_or("", String::as_str))
            .y_desc("voxels per bin (linear, black)")
            .y_label_formatter(&|c| format!("{}", c.round() as u64))
            .axis_desc_style(("sans-serif", 14))
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(plot_err)?;
        chart
            .configure_secondary_axes()
            .y_desc("voxels per bin (log, grey)")
            .y_label_formatter(&|c| format!("{}", c.round() as u64))
            .axis_desc_style(("sans-serif", 14))
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(plot_err)?;
        let bar = |i: usize| (a.min + i as f64 * a.width(), a.min + (i + 1) as f64 * a.width());
        let grey = RGBColor(170, 170, 170);
        chart
            .draw_secondary_series(self.counts.iter().enumerate().filter(|(_, c)| **c > 0).map(|(i, &c)| {
                let (x0, x1) = bar(i);
                Rectangle::new([(x0, 1.0), (x1, c as f64)], grey.filled())
            }))
            .map_err(plot_err)?;
        chart
            .draw_series(self.counts.iter().enumerate().filter(|(_, c)| **c > 0).map(|(i, &c)| {
                let (x0, x1) = bar(i);
                Rectangle::new([(x0, 0.0), (x1, c as f64)], BLACK.filled())
            }))
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
        Ok(true)
    }
}

/// Size of the figure of a 3D histogram's three primary-plane projections, pixels.
pub const PROJECTIONS_SIZE: (u32, u32) = (1260, 470);

impl Histogram {
    /// The colour-volume picture of a 3D histogram ([`Histogram::rgb_projections`])
    /// as a figure: the three projections side by side, each over its two
    /// channels' axes in their units, titled `title`; None unless 3D.
    pub fn projections_figure(&self, scale: Scale, title: &str) -> Result<Option<Rgb>, String> {
        let Some(img) = self.rgb_projections(scale) else { return Ok(None) };
        mdtf_volume::register_figure_font();
        let (w, h) = PROJECTIONS_SIZE;
        let mut pixels = vec![255u8; (w * h * 3) as usize];
        let bins: Vec<usize> = self.axes.iter().map(|a| a.bins).collect();
        // (first axis, second axis, the panel's left column in `img`)
        let panels = [(0usize, 1usize, 0usize), (0, 2, bins[0] + GAP), (1, 2, 2 * (bins[0] + GAP))];
        let mut rects = Vec::new();
        {
            let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
            let root = root.titled(title, ("sans-serif", 18)).map_err(plot_err)?;
            for (area, &(a, b, _)) in root.split_evenly((1, 3)).iter().zip(&panels) {
                let (xa, ya) = (&self.axes[a], &self.axes[b]);
                let mut chart = ChartBuilder::on(area)
                    .margin(10)
                    .x_label_area_size(44)
                    .y_label_area_size(64)
                    .build_cartesian_2d(xa.min..xa.max, ya.min..ya.max)
                    .map_err(plot_err)?;
                chart
                    .configure_mesh()
                    .disable_mesh()
                    .x_desc(axis_label(&xa.name))
                    .y_desc(axis_label(&ya.name))
                    .axis_desc_style(("sans-serif", 12))
                    .label_style(("sans-serif", 11))
                    .draw()
                    .map_err(plot_err)?;
                rects.push(chart.plotting_area().get_pixel_range());
            }
            root.present().map_err(plot_err)?;
        }
        for (rect, &(a, b, x0)) in rects.iter().zip(&panels) {
            each_plot_pixel(rect, (bins[a], bins[b]), |x, y, ia, ib, _, _| {
                let from = 3 * ((img.height - 1 - ib) * img.width + x0 + ia);
                let to = 3 * (y * w as usize + x);
                pixels[to..to + 3].copy_from_slice(&img.pixels[from..from + 3]);
            });
        }
        Ok(Some(Rgb { width: w as usize, height: h as usize, pixels }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_title_keeps_18_px_when_it_fits_and_shrinks_to_fit_its_area_when_it_does_not() {
        mdtf_volume::register_figure_font();
        // the heat map's part of a figure, beside its colour bar
        let (w, h) = (640, 620);
        let mut pixels = vec![0u8; (w * h * 3) as usize];
        let area = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
        assert_eq!(caption_size(&area, "hist_v_g of b256.nrrd"), 18);
        let long = "default opacity over the (v, g) histogram of built-in ErfSphere phantom, 128^3, sigma 3";
        let size = caption_size(&area, long);
        let width = |size: u32| {
            let style = TextStyle::from(("sans-serif", size).into_font());
            area.estimate_text_size(long, &style).map(|(w, _)| w).unwrap_or(0)
        };
        assert!(size < 18 && width(18) > w - 24, "18 px would not fit: {} px wide", width(18));
        assert!(width(size) <= w - 24 && width(size + 1) > w - 24, "{size} px: the largest that fits");
    }
}
