//! gsplat's golden render cases (`tests/fixtures/splat/<name>`): the scene, its cameras and
//! render settings, and the deformation of the deformed case.

use crate::{fixture, read_npy};
use r4d_splat::{load_cameras, CameraSet, Deformation, Gaussians, RenderSettings};
use std::path::PathBuf;

/// The cases, by folder name.
pub const SCENES: [&str; 5] = [
    "sh0_basic",
    "sh3_shell_bg",
    "aniso_near_bg",
    "antialiased_sh2_white",
    "deformed_sh3",
];

/// One golden case.
pub struct Case {
    /// Its folder (the golden arrays are read from here).
    pub dir: PathBuf,
    /// The scene.
    pub scene: Gaussians,
    /// The deformation (`deformed_means.npy`, `deformation_F.npy`), when the case has one.
    pub deform: Option<Deformation>,
    /// The cameras, background and mode.
    pub cams: CameraSet,
}

/// Reads case `name`.
pub fn load(name: &str) -> Case {
    let dir = fixture(&format!("splat/{name}"));
    let scene = r4d_splat::ply::read_gaussians(&dir.join("scene.ply")).unwrap();
    let cams = load_cameras(&dir.join("cameras.json")).unwrap();
    let deform = dir.join("deformed_means.npy").exists().then(|| {
        let m = read_npy(&dir.join("deformed_means.npy"));
        let f = read_npy(&dir.join("deformation_F.npy"));
        Deformation {
            means: m
                .data
                .chunks(3)
                .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
                .collect(),
            f: f.data
                .chunks(9)
                .map(|c| [0, 1, 2].map(|r| [0, 1, 2].map(|k| c[3 * r + k] as f32)))
                .collect(),
        }
    });
    Case {
        dir,
        scene,
        deform,
        cams,
    }
}

/// The case's render settings (background and mode from its cameras file).
pub fn settings(c: &Case) -> RenderSettings {
    RenderSettings {
        background: c.cams.background.unwrap_or([0.0; 3]),
        mode: c.cams.mode.unwrap_or_default(),
    }
}
