//! `report.html`: one self-contained page per run, to open in a browser.
//! It holds what the run read (the input's grid and range), what it did
//! (the resolved settings, the stage table), what it found (the boundaries
//! in the histogram volume, the tracing's counts), every figure with a
//! caption, the warnings, and how to decode the pack. Figures are linked
//! by relative paths inside the output folder; there is no script, font
//! or stylesheet from the network.

use crate::run::RunReport;
use mdtf_pack::Manifest;
use std::fmt::Write as _;
use std::path::Path;

/// The page's file name in the output folder.
pub const REPORT_PAGE: &str = "report.html";

/// A figure of the run: a PNG inside the output folder and what it shows.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// Path relative to the output folder, with `/` separators.
    pub file: String,
    /// One or two sentences saying what the picture shows and how to read it.
    pub caption: String,
}

/// Figures a run may write, in the order the page shows them, with their captions.
const KNOWN_FIGURES: [(&str, &str); 8] = [
    (
        "preview.png",
        "The pack rendered from its manifest as a renderer would (azimuth 30 deg, elevation 20 deg, \
         step 0.5 voxel), with the transfer function the pack holds.",
    ),
    (
        "histogram/hist_v_g.png",
        "Joint histogram of the value v and the gradient magnitude g, log counts. A boundary between \
         two materials draws an arch from one material's value to the other's, highest at the \
         boundary's centre (Kindlmann and Durkin).",
    ),
    (
        "histogram/opacity.png",
        "The default opacity from the histogram volume: a tent of the position function p(v, g), \
         opaque where a voxel sits on a boundary's centre.",
    ),
    (
        "histogram/hist_v_inv_g.png",
        "Joint histogram of v and 1/g, the domain of the peak-finding transfer function, log counts.",
    ),
    (
        "histogram/normal_vs_stretched.png",
        "The traced voxels' (v, g) histogram beside their (v, g_hit): tracing each voxel to its \
         boundary gives it the boundary's peak gradient, so each arch becomes a short flat run.",
    ),
    (
        "boundary/boundary_report.png",
        "Boundary tracing (the distance paper's Fig. 2) over log10(1 - dot), how far the gradient at a \
         voxel turns from the one at its boundary hit: the share of the hit voxels per bin (and cumulative), \
         their mean distance to the boundary and their mean g.",
    ),
    (
        "histogram/hist_v_g_hit.png",
        "The stretched histogram alone: v against the gradient magnitude at each traced voxel's boundary \
         hit, log counts.",
    ),
    ("histogram/hist_v.png", "Histogram of the value v, log and linear bars overlaid."),
];

/// The figures present in `dir`, the known ones first with their captions,
/// then any other PNG of the histogram and boundary folders by name.
pub fn figures_in(dir: &Path) -> Vec<Figure> {
    let mut figures: Vec<Figure> = KNOWN_FIGURES
        .iter()
        .filter(|(f, _)| dir.join(f).is_file())
        .map(|(f, c)| Figure { file: (*f).into(), caption: (*c).into() })
        .collect();
    for sub in ["histogram", "boundary"] {
        let Ok(entries) = std::fs::read_dir(dir.join(sub)) else { continue };
        let mut others: Vec<String> = entries
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.ends_with(".png"))
            .map(|n| format!("{sub}/{n}"))
            .filter(|f| !figures.iter().any(|k| &k.file == f))
            .collect();
        others.sort();
        figures.extend(others.into_iter().map(|f| {
            let caption = if f.starts_with("histogram/tf_") {
                "A transfer-function table of the pack over the histogram of its two channels: the table's \
                 colour mixed into the counts (greys) by the square root of its opacity, the boundaries \
                 found drawn as their model arches."
            } else if f.starts_with("histogram/hist_") {
                "A joint histogram of the channels its name lists (first to the right, second upward), log counts."
            } else {
                "A figure of the run."
            };
            Figure { caption: caption.into(), file: f }
        }));
    }
    figures
}

/// What the page shows beside the run report.
pub struct PageInputs<'a> {
    /// The run's report.
    pub report: &'a RunReport,
    /// The resolved settings of the run as TOML.
    pub settings: &'a str,
    /// The pack's manifest, when the run wrote a volume pack.
    pub manifest: Option<&'a Manifest>,
    /// The pack's provenance (of a volume or a mesh pack).
    pub provenance: Option<&'a mdtf_pack::Provenance>,
    /// The pack's Gaussian primitives (`gaussians.json`), when it has them.
    pub gaussians: Option<&'a [mdtf_pack::GaussianPrimitive]>,
    /// The figures, in order.
    pub figures: &'a [Figure],
}

/// The page as HTML.
pub fn render(page: &PageInputs) -> String {
    let r = page.report;
    let mut h = String::with_capacity(16 * 1024);
    let title = format!("mdtf run of {}", r.input);
    let _ = write!(
        h,
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <title>{}</title><style>{STYLE}</style></head><body>\n<h1>{}</h1>\n",
        esc(&title),
        esc(&title)
    );
    let _ = writeln!(
        h,
        "<p class=\"sub\">pipeline <code>{}</code>, output <code>{}</code>, {:.2} s in all</p>",
        esc(&r.pipeline),
        esc(&r.output),
        r.total_seconds
    );
    input_section(&mut h, r, page.provenance);
    warnings_section(&mut h, r);
    boundaries_section(&mut h, r);
    if let Some(g) = page.gaussians {
        gaussians_section(&mut h, g, &r.fields);
    }
    figures_section(&mut h, page.figures);
    stages_section(&mut h, r);
    if let Some(m) = page.manifest {
        pack_section(&mut h, m, &r.units);
    }
    let _ = writeln!(
        h,
        "<h2>Settings</h2>\n<p>The pipeline as this run resolved it (defaults filled in); \
         run it again with <code>mdtf run FILE.toml</code>.</p>\n<pre>{}</pre>",
        esc(page.settings)
    );
    h.push_str("</body></html>\n");
    h
}

/// Writes the page into `dir` (atomically).
pub fn write(dir: &Path, page: &PageInputs) -> std::io::Result<()> {
    let html = render(page);
    mdtf_volume::write_file_atomically(&dir.join(REPORT_PAGE), |w| w.write_all(html.as_bytes()))
        .map_err(std::io::Error::other)
}

const STYLE: &str = "body{font-family:system-ui,sans-serif;max-width:72rem;margin:1.5rem auto;padding:0 1rem;\
color:#222;line-height:1.45}h1{font-size:1.5rem;margin-bottom:.2rem}h2{font-size:1.2rem;margin-top:2rem;\
border-bottom:1px solid #ccc}.sub{color:#555;margin-top:0}table{border-collapse:collapse;margin:.5rem 0}\
td,th{border:1px solid #ccc;padding:.2rem .5rem;text-align:left;vertical-align:top}td.n{text-align:right;\
font-variant-numeric:tabular-nums}th{background:#f2f2f2}.warn{background:#fff4d6;border-left:4px solid #e0a800;\
padding:.4rem .8rem}figure{display:inline-block;vertical-align:top;margin:.5rem 1rem 1rem 0;max-width:34rem}\
figure img{max-width:100%;border:1px solid #ddd}figcaption{font-size:.9rem;color:#333}\
pre{background:#f7f7f7;padding:.6rem;overflow-x:auto}.swatch{display:inline-block;width:1em;height:1em;\
border:1px solid #888;vertical-align:middle}";

fn input_section(h: &mut String, r: &RunReport, provenance: Option<&mdtf_pack::Provenance>) {
    let [nx, ny, nz] = r.dims;
    let [sx, sy, sz] = r.spacing;
    let _ = writeln!(h, "<h2>Input</h2>\n<table>");
    row(h, "file", &esc(&r.input));
    if let Some(format) = provenance.and_then(|p| p.input_format.as_deref()) {
        row(h, "format", &esc(format));
    }
    if let Some(sha) = provenance.and_then(|p| p.input_sha256.as_deref()) {
        row(h, "SHA-256", &esc(sha));
    }
    row(h, "grid", &format!("{nx} x {ny} x {nz} ({} voxels)", nx * ny * nz));
    let length = r.units.lengths_name();
    row(h, "spacing", &format!("{sx} x {sy} x {sz} {length}"));
    row(h, "units", &esc(&units_line(&r.units)));
    if !r.fields.is_empty() {
        row(h, "fields", &esc(&r.fields.join(", ")));
    }
    if let Some([lo, hi]) = r.value_range {
        row(h, "value range", &format!("{} .. {} {} (finite values)", num(lo), num(hi), esc(r.units.value_name())));
    }
    h.push_str("</table>\n");
}

/// The unit of g: the input's (e.g. "HU/mm"), else the generic one.
fn g_unit(units: &mdtf_volume::Units) -> String {
    units.of_channel("g").unwrap_or_else(|| "value units per world unit".into())
}

/// What the input states of its units, in words.
fn units_line(u: &mdtf_volume::Units) -> String {
    let said = |unit: &Option<String>, what: &str| match unit {
        Some(unit) => format!("{what} in {unit}"),
        None => format!("{what} in units the input does not state"),
    };
    format!("{}; {}", said(&u.value, "values"), said(&u.length, "lengths"))
}

fn warnings_section(h: &mut String, r: &RunReport) {
    if r.warnings.is_empty() {
        return;
    }
    h.push_str("<h2>Warnings</h2>\n<div class=\"warn\"><ul>\n");
    for w in &r.warnings {
        let _ = writeln!(h, "<li>{}</li>", esc(w));
    }
    h.push_str("</ul></div>\n");
}

fn boundaries_section(h: &mut String, r: &RunReport) {
    if r.hvol_built {
        h.push_str("<h2>Boundaries found</h2>\n");
        if r.boundaries.is_empty() {
            h.push_str(
                "<p>No boundary stood out in the (v, g) histogram: no pair of the materials found (the dips \
                 of the median g of its value columns, listed in histogram/hvol.json) has an arch between them \
                 that explains the voxels above the noise. The default transfer functions show one fallback \
                 boundary placed by percentiles (from the background value to the 99th percentile of the values) \
                 at opacity 0.5. To try: a smoothing derivative kernel for noisy data (derive.kernel = \
                 \"gauss:1.5\"), or a TF of your own (pack.tf) drawn over the (v, g) histogram figure.</p>\n",
            );
        } else {
            let (v_unit, length, g_unit) = (r.units.value_name(), r.units.lengths_name(), g_unit(&r.units));
            let _ = writeln!(
                h,
                "<p>The pairs of materials whose erf-edge arch stands out in the (v, g) histogram, strongest first; \
                 confidence is the share of the voxels above the noise along the arch that it explains. \
                 The default transfer functions give each its colour and surface opacity (what a ray crossing \
                 it accumulates: the smallest inner surface opaque, larger ones fainter, one meeting the \
                 background at most 0.3); a TF of one value (gaussian-tf's Gaussians, peak finding's \
                 isosurfaces) shows it at its isovalue, its centre unless another boundary sharing a material \
                 passes there.</p>\n<table><tr><th>#</th><th>colour</th>\
                 <th>low material v ({v})</th><th>centre v ({v})</th><th>high material v ({v})</th><th>peak g ({g})</th>\
                 <th>sigma ({l})</th><th>core voxels (within sigma / 2 of its centre)</th><th>confidence</th><th>meets the background</th>\
                 <th>surface opacity</th><th>isovalue of one-value TFs ({v})</th></tr>",
                v = esc(v_unit),
                g = esc(&g_unit),
                l = esc(length),
            );
            let n = r.boundaries.len();
            let arches = crate::pack_inputs::arches_from(&r.boundaries);
            let opacity = mdtf_pack::boundary_opacities(&arches);
            for ((k, b), a) in r.boundaries.iter().enumerate().zip(opacity) {
                let [cr, cg, cb] = mdtf_pack::boundary_colour(k, n).map(|c| (c * 255.0).round() as u8);
                let _ = writeln!(
                    h,
                    "<tr><td class=\"n\">{}</td><td><span class=\"swatch\" style=\"background:rgb({cr},{cg},{cb})\">\
                     </span></td><td class=\"n\">{} (sd {})</td><td class=\"n\">{}</td><td class=\"n\">{} (sd {})</td>\
                     <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
                     <td class=\"n\">{:.2}</td><td>{}</td><td class=\"n\">{a:.3}</td><td class=\"n\">{}</td></tr>",
                    k + 1,
                    num(b.v_low),
                    num(b.v_low_spread),
                    num(b.v_centre),
                    num(b.v_high),
                    num(b.v_high_spread),
                    num(b.g_peak),
                    num(b.sigma),
                    b.core_voxels,
                    b.confidence,
                    if b.meets_background { "yes" } else { "no" },
                    num(mdtf_pack::isovalue(&arches, k))
                );
            }
            h.push_str("</table>\n");
        }
    }
    if let Some(b) = &r.boundary {
        tracing_section(h, b, &r.units);
    }
}

/// The tracing's thresholds and what became of the voxels, as tables.
fn tracing_section(h: &mut String, b: &crate::report::BoundarySummary, units: &mdtf_volume::Units) {
    let (p, c) = (&b.resolved, &b.counts);
    let (g_unit, length) = (g_unit(units), units.lengths_name());
    h.push_str(
        "<h2>Boundary tracing</h2>\n<p>Each voxel with g at or above g_min was traced along its gradient, \
         towards larger g, to the nearest zero crossing of f''; a crossing whose g is below g_hit_min is \
         rejected as noise.</p>\n<table><tr><th>setting</th><th>value</th></tr>\n",
    );
    for (name, value) in [
        (
            "noise floor (twice the median g, at least 1e-3 of the value range per voxel)",
            format!("{} {g_unit}", num(p.noise_floor)),
        ),
        ("g_min (traced from)", format!("{} {g_unit}", num(p.g_min))),
        (
            match p.g_hit_min_of_boundaries {
                true => {
                    "g_hit_min (kept crossings; half the least peak g of the boundaries found, under twice the floor)"
                }
                false => "g_hit_min (kept crossings)",
            },
            format!("{} {g_unit}", num(p.g_hit_min)),
        ),
        ("step", format!("{} {length}", num(p.step))),
        ("d_max (longest trace)", format!("{} {length}", num(p.d_max))),
        ("tolerance of the crossing", format!("{} {length}", num(p.tolerance))),
        (
            "Fig. 2 report's g at the voxel / at the hit (the paper's 5 / 20 on 8-bit data, times the range / 255)",
            format!(
                "{} / {} {g_unit} (range {}: {})",
                num(p.fig2_g_min),
                num(p.fig2_g_hit_min),
                num(p.fig2_range),
                if p.fig2_range_of_boundaries { "the span of the boundaries' materials" } else { "min to max" }
            ),
        ),
    ] {
        row(h, name, &esc(&value));
    }
    h.push_str("</table>\n<table><tr><th>voxels</th><th>count</th><th>share</th></tr>\n");
    let total = (c.not_traced + c.hits + c.no_crossing + c.rejected).max(1) as f64;
    for (name, n) in [
        ("hit a boundary (kept)", c.hits),
        ("traced, no crossing within d_max", c.no_crossing),
        ("traced, crossing rejected (g below g_hit_min)", c.rejected),
        ("not traced (g below g_min)", c.not_traced),
    ] {
        let _ = writeln!(
            h,
            "<tr><td>{name}</td><td class=\"n\">{n}</td><td class=\"n\">{:.1} %</td></tr>",
            100.0 * n as f64 / total
        );
    }
    h.push_str("</table>\n");
}

fn gaussians_section(h: &mut String, gaussians: &[mdtf_pack::GaussianPrimitive], fields: &[String]) {
    let _ = writeln!(
        h,
        "<h2>Gaussian transfer function</h2>\n<p>The primitives of <code>pack/gaussians.json</code> (from the TF \
         file, else the defaults the data gave: on one field a triangular Gaussian at each boundary found, on \
         several a Gaussian at each material of the fields' joint histogram but the background). Width: how far \
         along each field's axis from the centre the density falls to exp(-1/2), 1 / (sqrt(2) |K's column|) \
         (times the gradient for a triangular one).</p>\n<table><tr>\
         <th>#</th><th>colour</th><th>kind</th><th>centre</th><th>width</th><th>opacity per voxel</th></tr>"
    );
    for (k, g) in gaussians.iter().enumerate() {
        let [cr, cg, cb] = g.colour.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
        let name =
            |a: usize| fields.get(a).cloned().unwrap_or_else(|| if a == 0 { "v".into() } else { format!("field{a}") });
        let centre: Vec<String> =
            g.centre.iter().enumerate().map(|(a, c)| format!("{} {}", name(a), num(*c))).collect();
        let width: Vec<String> = (0..g.fields())
            .map(|a| {
                let column = g.k.iter().map(|row| row.get(a).copied().unwrap_or(0.0).powi(2)).sum::<f64>().sqrt();
                let sd = if column > 0.0 { 1.0 / (std::f64::consts::SQRT_2 * column) } else { f64::INFINITY };
                format!("{} {}", name(a), num(sd))
            })
            .collect();
        let kind = if g.triangular { "triangular (width grows with the gradient)" } else { "full" };
        let _ = writeln!(
            h,
            "<tr><td class=\"n\">{}</td><td><span class=\"swatch\" style=\"background:rgb({cr},{cg},{cb})\"></span>\
             </td><td>{kind}</td><td>{}</td><td>{}</td><td class=\"n\">{}</td></tr>",
            k + 1,
            esc(&centre.join(", ")),
            esc(&width.join(", ")),
            num(g.alpha_max)
        );
    }
    h.push_str("</table>\n");
}

fn figures_section(h: &mut String, figures: &[Figure]) {
    if figures.is_empty() {
        return;
    }
    h.push_str("<h2>Figures</h2>\n");
    for f in figures {
        let _ = writeln!(
            h,
            "<figure><a href=\"{0}\"><img src=\"{0}\" alt=\"{0}\"></a><figcaption><code>{0}</code>: {1}</figcaption></figure>",
            esc(&f.file),
            esc(&f.caption)
        );
    }
}

fn stages_section(h: &mut String, r: &RunReport) {
    h.push_str(
        "<h2>Stages</h2>\n<table><tr><th>stage</th><th>seconds</th><th>Mvoxel/s</th><th>peak memory (MiB)</th>\
         <th>wrote</th></tr>\n",
    );
    for s in &r.stages {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=\"n\">{:.3}</td><td class=\"n\">{:.1}</td><td class=\"n\">{:.0}</td><td>{}</td></tr>",
            esc(&s.stage),
            s.seconds,
            s.mvoxel_per_s,
            s.peak_mib,
            esc(&s.outputs.join(", "))
        );
    }
    let _ = writeln!(
        h,
        "<tr><th>total</th><td class=\"n\">{:.3}</td><td></td><td class=\"n\">{:.0}</td><td></td></tr></table>",
        r.total_seconds, r.peak_mib
    );
}

fn pack_section(h: &mut String, m: &Manifest, units: &mdtf_volume::Units) {
    let _ = writeln!(
        h,
        "<h2>The pack</h2>\n<p>Profile <code>{}</code>, described in full by <code>pack/manifest.json</code>. \
         Each texture is a raw file of little-endian samples (components fastest, then x, y, z) with a \
         detached NRRD header. A channel's value is <code>offset + scale x code</code>.</p>",
        esc(&m.profile)
    );
    h.push_str("<table><tr><th>texture</th><th>files</th><th>type</th><th>components</th></tr>\n");
    for t in &m.textures {
        let dtype = serde_json::to_value(t.dtype).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default();
        let order: Vec<&str> = t.component_order.iter().map(|c| c.as_deref().unwrap_or("-")).collect();
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td><code>pack/{}</code>, <code>pack/{}</code></td><td>{}</td><td>{}</td></tr>",
            esc(&t.name),
            esc(&t.header),
            esc(&t.data),
            esc(&dtype),
            esc(&order.join(", "))
        );
    }
    h.push_str(
        "</table>\n<table><tr><th>channel</th><th>meaning</th><th>units</th><th>in</th><th>offset</th>\
         <th>scale</th><th>range</th></tr>\n",
    );
    for c in &m.channels {
        // in the units the input states, where it states them
        let unit = units.of_channel(&c.name).unwrap_or_else(|| c.units.clone());
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}[{}]</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{} .. {}</td></tr>",
            esc(&c.name),
            esc(&c.meaning),
            esc(&unit),
            esc(&c.texture),
            c.component,
            num(c.decode.offset),
            num(c.decode.scale),
            num(c.range[0]),
            num(c.range[1])
        );
    }
    h.push_str("</table>\n");
    if !m.luts.is_empty() {
        h.push_str("<table><tr><th>table</th><th>meaning</th><th>axes</th><th>file</th></tr>\n");
        for l in &m.luts {
            let axes: Vec<String> = l
                .axes
                .iter()
                .map(|a| format!("{} ({} cells, {} .. {})", a.channel, a.size, num(a.min), num(a.max)))
                .collect();
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td><code>pack/{}</code></td></tr>",
                esc(&l.name),
                esc(&l.meaning),
                esc(&axes.join(" x ")),
                esc(l.file_u8.as_deref().unwrap_or(&l.file_f32))
            );
        }
        h.push_str("</table>\n");
    }
}

fn row(h: &mut String, key: &str, value_html: &str) {
    let _ = writeln!(h, "<tr><th>{key}</th><td>{value_html}</td></tr>");
}

/// A number with about 4 significant digits, without trailing noise.
fn num(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let digits = (3 - x.abs().log10().floor() as i32).clamp(0, 8) as usize;
    let s = format!("{x:.digits$}");
    if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s }
}

/// `s` with the five characters HTML gives meaning to escaped.
fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_escaped_and_numbers_keep_four_digits() {
        assert_eq!(esc("a<b & \"c\" 'd'>"), "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt;");
        assert_eq!(num(108.30873870849), "108.3");
        assert_eq!(num(0.0012345), "0.001234");
        assert_eq!(num(-119.22), "-119.2");
        assert_eq!(num(254.0), "254");
        assert_eq!(num(12345.6), "12346");
    }
}
