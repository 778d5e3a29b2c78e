//! Checks of a rendered video against its reference (shapes, finiteness, gradient length).

use crate::error::{Input, LossError};
use crate::real::Real;
pub(crate) use r4d_frames::Video;

/// Checks that `rendered` and `reference` have the same shape and finite values.
pub(crate) fn check_pair<T: Real>(
    rendered: &Video<T>,
    reference: &Video<T>,
) -> Result<(), LossError> {
    check_shapes(rendered, reference)?;
    reference.check_finite(Input::Reference)?;
    Ok(rendered.check_finite(Input::Rendered)?)
}

/// Checks that `rendered` has the reference's shape and finite values (for a reference
/// checked once, when a loss is built).
pub(crate) fn check_rendered<T: Real>(
    rendered: &Video<T>,
    reference: &Video<T>,
) -> Result<(), LossError> {
    check_shapes(rendered, reference)?;
    Ok(rendered.check_finite(Input::Rendered)?)
}

fn check_shapes<T: Real>(rendered: &Video<T>, reference: &Video<T>) -> Result<(), LossError> {
    if reference.frames() != rendered.frames() {
        return Err(LossError::FrameCount {
            reference: reference.frames(),
            rendered: rendered.frames(),
        });
    }
    if (reference.height(), reference.width()) != (rendered.height(), rendered.width()) {
        return Err(LossError::FrameSize {
            reference: (reference.height(), reference.width()),
            rendered: (rendered.height(), rendered.width()),
        });
    }
    Ok(())
}

/// Checks a gradient buffer's length.
pub(crate) fn check_grad_len<T: Real>(rendered: &Video<T>, grad: &[T]) -> Result<(), LossError> {
    if grad.len() != rendered.data().len() {
        return Err(LossError::GradientLength {
            expected: rendered.data().len(),
            got: grad.len(),
        });
    }
    Ok(())
}
