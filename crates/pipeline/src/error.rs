//! Errors of a run: the stage that failed and the stage library's own typed
//! error, kept as it was raised, so that a caller can match on its kind
//! (as bindings to other languages will need). Stage libraries name
//! parameters as a settings file does (`boundary.tolerance`); the CLI maps
//! them to its flags when it prints.

/// The typed error a stage library (or the run's own bookkeeping) raised.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// Reading or writing a volume, or the output folder.
    #[error("{0}")]
    Volume(#[from] mdtf_volume::VolumeError),
    /// Derivatives.
    #[error("{0}")]
    Derive(#[from] mdtf_derive::DeriveError),
    /// The bilateral pre-filter (its parameters are `[prefilter]`'s).
    #[error("{}", prefilter_names(.0))]
    Bilateral(#[from] mdtf_bilateral::BilateralError),
    /// Boundary tracing.
    #[error("{0}")]
    Boundary(#[from] mdtf_boundary::BoundaryError),
    /// Histograms and the histogram volume.
    #[error("{0}")]
    Histogram(#[from] mdtf_histogram::HistogramError),
    /// The texture pack.
    #[error("{0}")]
    Pack(#[from] mdtf_pack::PackError),
    /// Meshing and the tetra tables.
    #[error("{0}")]
    Tetra(#[from] mdtf_tetra::TetraError),
    /// The preview.
    #[error("{0}")]
    Preview(#[from] mdtf_preview::PreviewError),
    /// The plan cannot be made (e.g. `keep` names an unknown channel).
    #[error("{0}")]
    Plan(#[from] crate::plan::PlanError),
    /// A file of the run (a report, a figure) could not be written.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// A slab's channels could not be read or derived (a run by slabs).
    #[error("{0}")]
    Channels(#[from] crate::blocks::ChannelError),
    /// A task of a run on a cluster failed for good.
    #[error("{0}")]
    Task(#[from] crate::blocks::TaskFailed),
    /// The memory budget cannot hold the smallest piece of a run by slabs.
    #[error("{0}")]
    Budget(#[from] crate::blocks::BudgetError),
    /// A report could not be serialised.
    #[error("{0}")]
    Json(#[from] serde_json::Error),
    /// A resumable run's error, its partial folder kept for a rerun with
    /// the same settings and input to resume.
    #[error(
        "{error} (the run's finished tasks are kept in {}: run it again with the same settings and input to \
         resume, or with resume=False to start afresh)",
        folder.display()
    )]
    Kept {
        /// What stopped the run.
        error: Box<StageError>,
        /// The partial folder kept.
        folder: std::path::PathBuf,
    },
    /// What no library error describes: an input the plan refuses, a
    /// channel missing where the plan promised it, a bad TF file.
    #[error("{0}")]
    Other(String),
}

/// The bilateral filter names its parameters `bilateral.*`; in a pipeline
/// they are set in `[prefilter]`.
fn prefilter_names(e: &mdtf_bilateral::BilateralError) -> String {
    e.to_string().replace("bilateral.", "prefilter.")
}

/// A failed run: the stage and its error. The stage's error is part of the
/// message, not a `source()` as well, so that a printed chain does not say it twice.
#[derive(Debug, thiserror::Error)]
#[error("{stage}: {error}")]
pub struct RunError {
    /// The stage's name, as in the run report ("input", "derive", "boundary", ...).
    pub stage: String,
    /// What went wrong (boxed: stage errors are large, and a `Result` carries its error inline).
    pub error: Box<StageError>,
}

/// Wraps a stage library's error as the failure of `stage`.
pub(crate) fn at<E: Into<StageError>>(stage: &str) -> impl Fn(E) -> RunError + Copy + '_ {
    move |e| RunError { stage: stage.into(), error: Box::new(e.into()) }
}

/// A failure of `stage` that no library error describes.
pub(crate) fn fail(stage: &str) -> impl Fn(String) -> RunError + Copy + '_ {
    move |message| RunError { stage: stage.into(), error: Box::new(StageError::Other(message)) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_error_keeps_its_type_and_the_prefilter_names_its_own_section() {
        let e =
            at("prefilter")(mdtf_bilateral::BilateralError::BadParameter { name: "bilateral.sigma_d", value: -1.0 });
        assert_eq!(e.to_string(), "prefilter: prefilter.sigma_d must be a positive number, got -1");
        assert!(matches!(*e.error, StageError::Bilateral(_)));
        assert!(std::error::Error::source(&e).is_none());
    }
}
