//! The `r4d dataset inspect --json` report. Its keys are a contract (see `docs/cli/data.md`):
//! `layout`, `gaussians_in_file`, `gaussians_after_opacity_filter`, `simulated_particles`,
//! `static_gaussians`, `normalisation` (`rotation`, `mean`, `scale`, `shift`, `formula`),
//! `parts` (`id`, `material`, `particles`, `E_Pa`, `nu`, `density_kg_m3`, `yield_stress_Pa`,
//! `plastic_viscosity_Pa_s`, `friction_angle_deg`), `cameras` (`name`, `width`, `height`, `fx`,
//! `fy`), `videos` (`path`, `frames`, `fps`, `width`, `height`, `camera`), `substep_dt`,
//! `frame_dt`, `ground_truth`; plus descriptive extras.

use crate::Dataset;
use r4d_mpm::BoundaryCondition;
use serde_json::{json, Value};

fn material_name(m: r4d_mpm::Material) -> String {
    serde_json::to_value(m)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_else(|| format!("{m:?}").to_lowercase())
}

fn boundary(b: &BoundaryCondition) -> Value {
    serde_json::to_value(b).unwrap_or(Value::Null)
}

pub(crate) fn summary(d: &Dataset) -> Value {
    let l = &d.link;
    let mut counts = vec![0usize; d.config.parts.len()];
    for &p in &d.particles.part {
        if let Some(c) = counts.get_mut(p as usize) {
            *c += 1;
        }
    }
    let parts: Vec<Value> = d
        .config
        .parts
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut v = json!({
                "id": i,
                "material": material_name(p.material),
                "particles": counts[i],
                "E_Pa": p.youngs_modulus_pa,
                "nu": p.poisson_ratio,
                "density_kg_m3": p.density_kg_m3,
                "yield_stress_Pa": p.yield_stress_pa,
                "plastic_viscosity_Pa_s": p.plastic_viscosity_pa_s,
                "friction_angle_deg": p.friction_angle_deg,
            });
            if d.physflow.is_some() {
                v["physflow"] =
                    serde_json::to_value(crate::PhysFlowUnits::from_si(p)).unwrap_or(Value::Null);
            }
            v
        })
        .collect();
    let t = &d.config.time;
    let frame_dt = t.substeps() as f64 * t.substep_dt;
    json!({
        "layout": d.layout.name(),
        "dir": d.dir.display().to_string(),
        "scene": d.name,
        "config_file": d.config_file.as_ref().map(|p| p.display().to_string()),
        "gaussian_file": d.gaussian_file.display().to_string(),
        "gaussians_in_file": d.gaussians_in_file,
        "gaussians_after_opacity_filter": d.gaussians_after_opacity_filter,
        "simulated_particles": d.particles.len(),
        "filling_particles": l.filled,
        "static_gaussians": d.static_gaussians(),
        "rendered_gaussians": d.scene.len(),
        "normalisation": {
            "rotation": l.rotation,
            "mean": l.centre,
            "scale": l.scale,
            "shift": l.shift,
            "formula": "x_sim = scale * (rotation * x_world - mean) + shift; x_world = rotation^T * ((x_sim - shift) / scale + mean)",
        },
        "grid": { "n_grid": d.config.domain.n_grid, "grid_lim": d.config.domain.grid_lim },
        "gravity": d.config.solver.gravity,
        "parts": parts,
        "boundary_conditions": d.config.boundary.iter().map(boundary).collect::<Vec<_>>(),
        "cameras": d.cameras.iter().map(|c| json!({
            "name": c.name, "width": c.width, "height": c.height, "fx": c.fx, "fy": c.fy,
            "cx": c.cx, "cy": c.cy,
            "fov_x_deg": 2.0 * (0.5 * c.width as f64 / c.fx).atan().to_degrees(),
            "fov_y_deg": 2.0 * (0.5 * c.height as f64 / c.fy).atan().to_degrees(),
        })).collect::<Vec<_>>(),
        "videos": d.views.iter().map(|v| json!({
            "path": v.video.path.display().to_string(),
            "frames": v.video.frames,
            "fps": v.video.fps,
            "width": v.video.width,
            "height": v.video.height,
            "camera": d.cameras[v.camera_index].name,
            "camera_index": v.camera_index,
        })).collect::<Vec<_>>(),
        "substep_dt": t.substep_dt,
        "frame_dt": frame_dt,
        "substeps_per_frame": t.substeps(),
        "frames": t.frames,
        "background": d.background,
        "ground_truth": !d.ground_truth.point_clouds.is_empty(),
        "ground_truth_frames": d.ground_truth.point_clouds.len(),
        "physflow": d.physflow.as_ref().map(|e| serde_json::to_value(e).unwrap_or(Value::Null)),
        "warnings": d.warnings,
    })
}
