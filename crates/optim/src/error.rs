//! The one error type of the fits (trajectory and video).

/// Errors of the fitting pipeline: the trajectory fit, the video fit, their initialisation
/// and resume.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// The simulator refused the setup or parameters.
    #[error(transparent)]
    Mpm(#[from] r4d_mpm::Error),
    /// The renderer refused the scene, a camera or a deformation (e.g. a simulation that
    /// exploded to non-finite positions).
    #[error(transparent)]
    Splat(#[from] r4d_splat::Error),
    /// The loss refused the videos.
    #[error(transparent)]
    Loss(#[from] r4d_loss::LossError),
    /// The optimiser refused a value or bound.
    #[error(transparent)]
    Optim(#[from] crate::Error),
    /// Inputs that do not fit together (targets, videos, cameras, parts, options).
    #[error("{0}")]
    Input(String),
    /// A loss or gradient became NaN or infinite.
    #[error("{0} is not finite (the simulation may have exploded: try smaller substeps or tighter bounds)")]
    NonFinite(String),
    /// The simulation exploded: a particle left the grid or became non-finite.
    #[error("the simulation exploded at {0} (try smaller substeps or tighter parameter bounds)")]
    Exploded(String),
    /// The compute backend failed (a GPU: no adapter, no device, a transfer, device lost).
    #[error("{backend} backend: {source}")]
    Backend {
        /// The backend's name (`"cpu"`, `"wgpu"`, ...).
        backend: String,
        /// What it reported.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A checkpoint that does not belong to this run.
    #[error("cannot resume: {0}")]
    Resume(String),
}

impl FitError {
    /// Whether this error belongs to the parameters evaluated (the simulation exploded, a
    /// value or gradient became non-finite, the simulator refused the parameters): another
    /// point of the search may well succeed.
    pub fn is_divergence(&self) -> bool {
        matches!(
            self,
            FitError::NonFinite(_) | FitError::Exploded(_) | FitError::Mpm(_) | FitError::Splat(_)
        )
    }

    /// A backend's error, named.
    pub fn backend(name: &str, e: impl std::error::Error + Send + Sync + 'static) -> FitError {
        FitError::Backend {
            backend: name.to_string(),
            source: Box::new(e),
        }
    }

    /// An error of a [`r4d_mpm::DynSimulation`] on backend `name`: the backend's own failures
    /// (a device lost, data of the wrong size) as [`FitError::Backend`], the simulator's
    /// refusals as [`FitError::Mpm`].
    pub fn sim(name: &str, e: r4d_mpm::Error) -> FitError {
        match e {
            r4d_mpm::Error::Backend(source) => FitError::Backend {
                backend: name.to_string(),
                source,
            },
            e @ r4d_mpm::Error::BackendOutput { .. } => FitError::backend(name, e),
            e => FitError::Mpm(e),
        }
    }

    /// A backend's error given as a message, named.
    pub fn backend_msg(name: &str, message: impl Into<String>) -> FitError {
        FitError::Backend {
            backend: name.to_string(),
            source: message.into().into(),
        }
    }
}

/// A malformed video, as the losses report it.
impl From<r4d_loss::FrameError> for FitError {
    fn from(e: r4d_loss::FrameError) -> Self {
        FitError::Loss(e.into())
    }
}
