//! `scode report`: the rate-distortion comparison people choose a codec by. Every model is
//! encoded by scode (fitted at several tolerances, raw mode) and by the baselines, Draco
//! (several `-qp`, `-cl`) and gltfpack (several `-vp`, `-cc`); every output is decoded and
//! measured against the input by `metrics`, and each scode point is paired, per baseline,
//! with the smallest file of no larger max and RMS error.
//! Results go to `report.md`, `results.csv` and PNG/SVG plots.
//!
//! Robustness: scode encodes run in a child process (the binary's hidden `report-step`
//! command, [`StepRunner::Subprocess`]) that is killed at the step time limit; a panic,
//! crash, overrun or error becomes an error row, never the end of the report.

mod brep;
mod discover;
mod model;
mod plot;
mod run;
mod steps;
mod table;

use std::path::{Path, PathBuf};

pub use brep::{BrepReference, FaceRuler};
pub use discover::{classify, discover_models, ModelInput, ModelSource};
pub use model::REFERENCE_CHORD_DIVISOR;
pub use plot::{corpus_chart, model_chart, render, Chart, Series};
pub use run::{
    equal_error, run_report, BaselineMatch, DracoStatus, EqualError, Measured, ModelReport,
    PointResult, Progress, Reference, Report, ReportOptions, DEFAULT_MODEL_TIMEOUT_SECS,
};
pub use steps::{
    find_draco, find_gltfpack, median, run_scode_job, run_scode_job_json, Baseline, DracoTools,
    ScodeJob, ScodeJobResult, Setting, StepRunner, RESULT_MARKER,
};
pub use table::{
    csv, csv_rows, markdown, missing_baselines, summarise, SettingSummary, CSV_HEADER,
};

use scode::error::{Error, Result};

/// Files written by [`write_report`].
#[derive(Clone, Debug, PartialEq)]
pub struct ReportFiles {
    pub markdown: PathBuf,
    pub csv: PathBuf,
    /// PNG and SVG plots; plot failures are listed in `plot_errors` instead.
    pub plots: Vec<PathBuf>,
    pub plot_errors: Vec<String>,
}

/// Writes `report.md`, `results.csv` and `plots/*.{png,svg}` into `out_dir`.
pub fn write_report(report: &Report, out_dir: &Path) -> Result<ReportFiles> {
    let plots_dir = out_dir.join("plots");
    std::fs::create_dir_all(&plots_dir).map_err(|e| Error::io(&plots_dir, e))?;
    let mut plots = Vec::new();
    let mut plot_errors = Vec::new();
    let mut draw = |chart: &Chart, stem: &str| -> Option<String> {
        let path = plots_dir.join(stem);
        match render(chart, &path) {
            Ok(()) => {
                plots.push(path.with_extension("png"));
                plots.push(path.with_extension("svg"));
                Some(format!("plots/{stem}.png"))
            }
            Err(e) => {
                plot_errors.push(format!("{stem}: {e}"));
                None
            }
        }
    };
    let corpus = corpus_chart(report);
    let corpus_plot = if corpus.series.is_empty() {
        None
    } else {
        draw(&corpus, "corpus")
    };
    let model_plots: Vec<Option<String>> = report
        .models
        .iter()
        .map(|m| {
            let chart = model_chart(m, &report.options.draco_cl);
            if m.error.is_some() || chart.series.is_empty() {
                None
            } else {
                draw(&chart, &m.slug())
            }
        })
        .collect();
    let md_path = out_dir.join("report.md");
    let md = markdown(report, corpus_plot.as_deref(), &model_plots);
    std::fs::write(&md_path, md).map_err(|e| Error::io(&md_path, e))?;
    let csv_path = out_dir.join("results.csv");
    std::fs::write(&csv_path, csv(report)).map_err(|e| Error::io(&csv_path, e))?;
    Ok(ReportFiles {
        markdown: md_path,
        csv: csv_path,
        plots,
        plot_errors,
    })
}
