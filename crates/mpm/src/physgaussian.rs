//! PhysGaussian import (in progress).
