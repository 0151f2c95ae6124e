//! `report.md` and `results.csv`.

use std::fmt::Write;

use super::run::{DracoStatus, Measured, ModelReport, Report};
use super::steps::{median, Baseline, Setting};

fn sci(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else {
        format!("{x:.2e}")
    }
}

fn ratio(x: Option<f64>) -> String {
    x.map_or("—".into(), |r| format!("{r:.2}"))
}

/// Escapes `|` so messages do not break Markdown tables.
fn md_cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// Summary statistics of one scode setting across models.
pub struct SettingSummary {
    pub setting: Setting,
    /// Equal-error ratios (best baseline / scode) of the models where some baseline point
    /// matched, in model order.
    pub ratios: Vec<f64>,
    /// The same per baseline (every baseline in [`Baseline::ALL`] order).
    pub per_baseline: Vec<(Baseline, Vec<f64>)>,
    /// Models where the scode point was measured.
    pub measured: usize,
    pub median_bits_per_vertex: f64,
    pub median_max_error: f64,
}

/// One [`SettingSummary`] per scode setting of the report.
pub fn summarise(report: &Report) -> Vec<SettingSummary> {
    report
        .scode_settings
        .iter()
        .map(|setting| {
            let measured: Vec<&Measured> = report
                .models
                .iter()
                .filter_map(|m| {
                    m.points
                        .iter()
                        .find(|p| &p.setting == setting)
                        .and_then(|p| p.measured())
                })
                .collect();
            let ratios = report
                .models
                .iter()
                .filter_map(|m| m.ratio_for(setting))
                .collect();
            let per_baseline = Baseline::ALL
                .iter()
                .map(|&b| {
                    let r = report
                        .models
                        .iter()
                        .filter_map(|m| m.equal_error_for(setting)?.for_baseline(b)?.ratio)
                        .collect();
                    (b, r)
                })
                .collect();
            SettingSummary {
                setting: *setting,
                ratios,
                per_baseline,
                measured: measured.len(),
                median_bits_per_vertex: median(
                    &measured
                        .iter()
                        .map(|m| m.rd.bits_per_vertex)
                        .collect::<Vec<_>>(),
                ),
                median_max_error: median(
                    &measured.iter().map(|m| m.rd.max_error).collect::<Vec<_>>(),
                ),
            }
        })
        .collect()
}

/// The Markdown report; `plots` names the plot files relative to the report (PNG paths of
/// the corpus plot and per model, `None` where no plot was drawn).
pub fn markdown(
    report: &Report,
    corpus_plot: Option<&str>,
    model_plots: &[Option<String>],
) -> String {
    let mut s = String::new();
    let n_models = report.models.len();
    let n_measured = report.models.iter().filter(|m| m.error.is_none()).count();
    let _ = writeln!(s, "# scode vs Draco and gltfpack: rate-distortion report\n");
    let _ = writeln!(
        s,
        "## Summary: best baseline bytes / scode bytes at equal error\n\n\
         For each scode point, the smallest file of each baseline whose max **and** RMS error \
         (both as fractions of the bounding-box diagonal, measured against the model's \
         reference: the exact B-rep for STEP parts, the input for mesh files) are no \
         larger; on a STEP part the baselines' files come from tessellations at several \
         chordal tolerances, so the smallest at each accuracy counts; the ratio is the smaller of the baselines' files / scode bytes (above 1: \
         scode is smaller), median over the models; the per-baseline medians follow. \
         {n_measured} of {n_models} models measured.\n"
    );
    for line in missing_baselines(report) {
        let _ = writeln!(s, "**{line}.** Its columns are empty.\n");
    }
    let _ = write!(
        s,
        "| scode setting | models measured | models matched | median best ratio | min | max |"
    );
    for b in Baseline::ALL {
        let _ = write!(s, " median {} / scode |", b.name());
    }
    let _ = writeln!(s, " median bits/vertex | median max error |");
    let _ = write!(s, "|---|---:|---:|---:|---:|---:|");
    for _ in Baseline::ALL {
        s.push_str("---:|");
    }
    let _ = writeln!(s, "---:|---:|");
    // A setting no model ran (raw mode on a report of STEP parts) has no row.
    let ran = |st: &Setting| {
        report
            .models
            .iter()
            .any(|m| m.points.iter().any(|p| &p.setting == st))
    };
    for sum in summarise(report).into_iter().filter(|s| ran(&s.setting)) {
        let (min, max) = sum
            .ratios
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &r| {
                (a.min(r), b.max(r))
            });
        let has = !sum.ratios.is_empty();
        let _ = write!(
            s,
            "| {} {} | {} | {} | **{}** | {} | {} |",
            sum.setting.codec(),
            sum.setting.label(),
            sum.measured,
            sum.ratios.len(),
            ratio(has.then(|| median(&sum.ratios))),
            ratio(has.then_some(min)),
            ratio(has.then_some(max)),
        );
        for (_, r) in &sum.per_baseline {
            let _ = write!(
                s,
                " {} ({}) |",
                ratio((!r.is_empty()).then(|| median(r))),
                r.len()
            );
        }
        let _ = writeln!(
            s,
            " {:.2} | {} |",
            sum.median_bits_per_vertex,
            sci(sum.median_max_error)
        );
    }
    let _ = writeln!(
        s,
        "\n\"models matched\": models where some baseline point was at least as accurate \
         (scode points more accurate than every baseline point have no ratio); per baseline, \
         the number of models it matched is in parentheses.\n"
    );
    if let Some(p) = corpus_plot {
        let _ = writeln!(
            s,
            "![bits per input vertex vs max error, all models]({p})\n\n\
             All models: bits per input vertex against max error (log scales), one colour per \
             codec; each model's points joined in error order.\n"
        );
    }
    // Per-model ratio table.
    let _ = writeln!(s, "## Equal-error ratio per model\n");
    let _ = write!(s, "| model | vertices | triangles |");
    for st in &report.scode_settings {
        let _ = write!(s, " {} {} |", st.codec(), st.label());
    }
    let _ = write!(s, "\n|---|---:|---:|");
    for _ in &report.scode_settings {
        let _ = write!(s, "---:|");
    }
    s.push('\n');
    for m in &report.models {
        let _ = write!(
            s,
            "| [{}](#{}) | {} | {} |",
            m.name,
            anchor(&m.name),
            m.vertices,
            m.triangles
        );
        if let Some(e) = &m.error {
            let _ = write!(s, " {} |", md_cell(e));
            for _ in 1..report.scode_settings.len() {
                s.push_str(" |");
            }
        } else {
            for st in &report.scode_settings {
                let cell = match m.points.iter().find(|p| &p.setting == st) {
                    Some(p) if p.measured().is_some() => ratio(m.ratio_for(st)),
                    Some(_) => "error".into(),
                    None => "not run".into(),
                };
                let _ = write!(s, " {cell} |");
            }
        }
        s.push('\n');
    }
    let _ = writeln!(s, "\n## Models\n");
    for (i, m) in report.models.iter().enumerate() {
        model_section(&mut s, m, model_plots.get(i).and_then(|p| p.as_deref()));
    }
    let o = &report.options;
    let _ = writeln!(s, "## How this was measured\n");
    let _ = writeln!(
        s,
        "- Every output is decoded (scode: `pipeline::decode_surface`, the default level and \
         limit projection a viewer shows; Draco: `draco_decoder` to PLY; gltfpack: its own \
         repack with `-noq` to float glb, read by scode's glTF reader) and compared with \
         the reference: a mesh file by sampled symmetric Hausdorff (max) and RMS distance, \
         100,000 area-weighted samples per side plus every vertex (the max also at points \
         along every edge longer than 2e-3 of the diagonal), as fractions of the joint \
         bounding-box diagonal (`metrics::measure_against_input`; scode files through \
         `pipeline::measure_file_against_input`, group by group, the same numbers as \
         `scode info --against`); a STEP part by the same sampling against its B-rep: the \
         distance to the exact plane, cylinder, cone, sphere or torus of the face nearest \
         to a point (where its projection lands on the face), to a tessellation 20x finer \
         than the tightest tolerance elsewhere, each model's section says which face is \
         which.\n\
         - Raw size: float32 positions + three u32 indices per triangle. Bits/vertex: per \
         input vertex.\n\
         - Times: median of up to {} runs (encodes slower than 2 s are timed once); Draco \
         times are the tools' own reports, gltfpack times the wall time of its process (its \
         decode: the repack above, an upper bound). scode decode includes subdivision and \
         limit projection.\n\
         - gltfpack's bytes include its glTF JSON (about 1 KB).\n\
         - Draco reads the input as float32 PLY, gltfpack as float32 glb, both without \
         groups; scode keeps CAD-face groups and names. Draco: {}. gltfpack: {}.\n\
         - Tolerances {:?} of the diagonal; per-step time limit {} s, per-model {} s. \
         Total wall time {:.0} s.\n",
        o.runs,
        match &report.draco {
            DracoStatus::Found(t) => format!("`{}`", t.encoder.display()),
            DracoStatus::Missing(m) => m.clone(),
        },
        match &report.gltfpack {
            Ok(p) => format!("`{}`", p.display()),
            Err(m) => m.clone(),
        },
        o.tolerances,
        o.step_timeout.as_secs(),
        o.model_timeout.as_secs(),
        report.seconds
    );
    s
}

/// One sentence per baseline that did not run (not installed), saying how to install it.
pub fn missing_baselines(report: &Report) -> Vec<String> {
    let mut out = Vec::new();
    if let DracoStatus::Missing(msg) = &report.draco {
        out.push(msg.clone());
    }
    if let Err(msg) = &report.gltfpack {
        out.push(msg.clone());
    }
    out
}

/// GitHub-style heading anchor of a model section.
fn anchor(name: &str) -> String {
    name.chars()
        .filter_map(|c| {
            if c.is_alphanumeric() || c == '-' || c == '_' {
                Some(c.to_ascii_lowercase())
            } else if c == ' ' {
                Some('-')
            } else {
                None
            }
        })
        .collect()
}

fn model_section(s: &mut String, m: &ModelReport, plot: Option<&str>) {
    let _ = writeln!(s, "### {}\n", m.name);
    if let Some(e) = &m.error {
        let _ = writeln!(s, "Not measured: {}\n", md_cell(e));
        return;
    }
    let _ = writeln!(
        s,
        "{} vertices, {} triangles, raw binary {} bytes; {:.1} s. Errors are measured \
         against {}.\n",
        m.vertices,
        m.triangles,
        m.raw_bytes,
        m.seconds,
        if m.reference.is_empty() {
            "the input mesh"
        } else {
            &m.reference
        }
    );
    if !m.faces.is_empty() {
        let _ = writeln!(
            s,
            "<details><summary>How each face is measured</summary>\n\n{}\n\n</details>\n",
            m.faces
                .iter()
                .map(|f| format!("- {}", md_cell(f)))
                .collect::<Vec<_>>()
                .join("\n")
        );
    }
    if let Some(p) = plot {
        let _ = writeln!(s, "![{} rate-distortion]({p})\n", m.name);
    }
    let _ = writeln!(
        s,
        "| codec | setting | bytes | bits/vertex | x smaller than raw | max error | RMS error | encode ms | decode ms | note |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|---|");
    for p in &m.points {
        match &p.outcome {
            Ok(me) => {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {:.2} | {:.1} | {} | {} | {:.1} | {:.1} | {} |",
                    p.setting.codec(),
                    p.label(),
                    me.rd.bytes,
                    me.rd.bits_per_vertex,
                    me.rd.ratio_to_raw,
                    sci(me.rd.max_error),
                    sci(me.rd.rms_error),
                    me.encode_ms,
                    me.decode_ms,
                    md_cell(me.note.as_deref().unwrap_or(""))
                );
            }
            Err(e) => {
                let _ = writeln!(
                    s,
                    "| {} | {} | | | | | | | | error: {} |",
                    p.setting.codec(),
                    p.label(),
                    md_cell(e)
                );
            }
        }
    }
    if !m.equal_error.is_empty() {
        equal_error_table(s, m);
    }
    s.push('\n');
}

/// The model's equal-error pairs: each scode point, the best baseline file at least as
/// accurate and the ratio of every baseline.
fn equal_error_table(s: &mut String, m: &ModelReport) {
    let _ = write!(
        s,
        "\n| scode point | scode bytes | max / RMS error | smallest baseline as accurate | its bytes | max / RMS error | best / scode |"
    );
    for b in Baseline::ALL {
        let _ = write!(s, " {} / scode |", b.name());
    }
    let _ = write!(s, "\n|---|---:|---|---|---:|---|---:|");
    for _ in Baseline::ALL {
        s.push_str("---:|");
    }
    s.push('\n');
    for e in &m.equal_error {
        let Some(sp) = m.points.get(e.scode) else {
            continue;
        };
        let Some(sm) = sp.measured() else { continue };
        let best = e
            .best
            .and_then(|j| m.points.get(j))
            .and_then(|p| p.measured().map(|d| (p, d)));
        let (dl, db, de) = match best {
            Some((p, d)) => (
                format!("{} {}", p.setting.codec(), p.label()),
                d.rd.bytes.to_string(),
                format!("{} / {}", sci(d.rd.max_error), sci(d.rd.rms_error)),
            ),
            None => ("none".into(), String::new(), String::new()),
        };
        let _ = write!(
            s,
            "| {} {} | {} | {} / {} | {} | {} | {} | **{}** |",
            sp.setting.codec(),
            sp.setting.label(),
            sm.rd.bytes,
            sci(sm.rd.max_error),
            sci(sm.rd.rms_error),
            dl,
            db,
            de,
            ratio(e.ratio)
        );
        for b in Baseline::ALL {
            let _ = write!(s, " {} |", ratio(e.for_baseline(b).and_then(|x| x.ratio)));
        }
        s.push('\n');
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Column names of `results.csv`.
pub const CSV_HEADER: &str = "model,codec,setting,bytes,bits_per_vertex,ratio_to_raw,max_error,rms_error,mean_error,encode_ms,decode_ms,equal_error_best_setting,equal_error_best_bytes,best_over_scode,draco_over_scode,gltfpack_over_scode,error";

/// One row per model and setting (one row per unmeasured model); errors relative to the
/// bounding-box diagonal; empty fields where there is no value.
pub fn csv(report: &Report) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for m in &report.models {
        s.push_str(&csv_rows(m));
    }
    s
}

/// The rows of one model in [`csv`] (no header).
pub fn csv_rows(m: &ModelReport) -> String {
    let mut s = String::new();
    if let Some(e) = &m.error {
        let _ = writeln!(s, "{},,,,,,,,,,,,,,,,{}", csv_field(&m.name), csv_field(e));
        return s;
    }
    for (i, p) in m.points.iter().enumerate() {
        let eq = m.equal_error.iter().find(|e| e.scode == i);
        let (ds, db) = match eq.and_then(|e| e.best).and_then(|j| m.points.get(j)) {
            Some(b) => (
                format!("{} {}", b.setting.codec(), b.setting.label()),
                b.measured()
                    .map_or(String::new(), |d| d.rd.bytes.to_string()),
            ),
            None => (String::new(), String::new()),
        };
        let fmt = |r: Option<f64>| r.map_or(String::new(), |r| format!("{r:.6}"));
        let r = fmt(eq.and_then(|e| e.ratio));
        let per: Vec<String> = Baseline::ALL
            .iter()
            .map(|&b| fmt(eq.and_then(|e| e.for_baseline(b)).and_then(|x| x.ratio)))
            .collect();
        match &p.outcome {
            Ok(me) => {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{:.6},{:.6},{:.6e},{:.6e},{:.6e},{:.3},{:.3},{},{},{},{},",
                    csv_field(&m.name),
                    p.setting.codec(),
                    p.label(),
                    me.rd.bytes,
                    me.rd.bits_per_vertex,
                    me.rd.ratio_to_raw,
                    me.rd.max_error,
                    me.rd.rms_error,
                    me.rd.mean_error,
                    me.encode_ms,
                    me.decode_ms,
                    csv_field(&ds),
                    db,
                    r,
                    per.join(",")
                );
            }
            Err(e) => {
                let _ = writeln!(
                    s,
                    "{},{},{},,,,,,,,,,,,,,{}",
                    csv_field(&m.name),
                    p.setting.codec(),
                    p.label(),
                    csv_field(e)
                );
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_quoting_and_anchors() {
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"x\""), "\"say \"\"x\"\"\"");
        assert_eq!(csv_field("plain"), "plain");
        assert_eq!(anchor("tess/screw_coarse.obj"), "tessscrew_coarseobj");
        assert_eq!(md_cell("a|b"), "a\\|b");
        assert_eq!(CSV_HEADER.split(',').count(), 17);
    }
}
