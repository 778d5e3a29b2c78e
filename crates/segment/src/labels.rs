//! Part labels of a scene's Gaussians: the file `r4d segment` writes and `r4d fit --parts`
//! reads (or a PLY with a `part` property), and their transfer onto simulation particles.

use crate::error::{Error, Result};
use r4d_splat::SimLink;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The most parts a parts file may declare (`num_parts`, or the largest `part` of a PLY plus
/// one): the most classes a mask can hold.
pub const MAX_PARTS: usize = 65_534;

/// Part labels per Gaussian: `{"num_parts": M, "class_names": [...], "labels": [...],
/// "confidence": [...], "counts": [...]}`; label -1 is static background.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PartLabels {
    /// Number of parts `M` (labels are in `-1 .. M`).
    pub num_parts: usize,
    /// Part names (may be empty).
    #[serde(default)]
    pub class_names: Vec<String>,
    /// One label per Gaussian, -1 for static.
    pub labels: Vec<i32>,
    /// Confidence per Gaussian (may be empty).
    #[serde(default)]
    pub confidence: Vec<f32>,
    /// Gaussians per part (may be empty).
    #[serde(default)]
    pub counts: Vec<usize>,
}

impl PartLabels {
    /// Labels with their confidences; `counts` is filled in. Panics if a label is outside
    /// `-1 .. num_parts` or the lengths differ (a bug of the caller, not an input).
    pub fn new(class_names: Vec<String>, labels: Vec<i32>, confidence: Vec<f32>) -> PartLabels {
        let num_parts = class_names.len();
        assert_eq!(labels.len(), confidence.len(), "one confidence per label");
        let mut counts = vec![0usize; num_parts];
        for &l in &labels {
            assert!(
                (-1..num_parts as i32).contains(&l),
                "label {l} outside -1 .. {num_parts}"
            );
            if l >= 0 {
                counts[l as usize] += 1;
            }
        }
        PartLabels {
            num_parts,
            class_names,
            labels,
            confidence,
            counts,
        }
    }

    /// Reads the JSON file or a PLY with an integer-valued `part` property (negative: static).
    pub fn load(path: &Path) -> Result<PartLabels> {
        let file = path.display().to_string();
        let bad = |message: String| Error::Parts {
            file: file.clone(),
            message,
        };
        let is_ply = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
        let labels = if is_ply {
            let ply = r4d_ply::read_ply(path)?;
            let col = ply
                .get("part")
                .ok_or_else(|| bad("no 'part' property (one label per Gaussian)".into()))?;
            let mut labels = Vec::with_capacity(col.len());
            for (i, &v) in col.iter().enumerate() {
                if !v.is_finite() || v.fract() != 0.0 {
                    return Err(bad(format!("vertex {i}: part {v} is not an integer")));
                }
                labels.push(if v < 0.0 { -1 } else { v as i32 });
            }
            let num_parts = labels.iter().map(|&l| l + 1).max().unwrap_or(0).max(0) as usize;
            PartLabels {
                num_parts,
                labels,
                ..Default::default()
            }
        } else {
            let text = r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES)
                .map_err(|e| bad(e.to_string()))?;
            return PartLabels::parse(&text, path);
        };
        labels.validate().map_err(bad)?;
        Ok(labels)
    }

    /// A parts JSON file's text, checked (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<PartLabels> {
        let bad = |message: String| Error::Parts {
            file: path.display().to_string(),
            message,
        };
        let labels: PartLabels =
            serde_json::from_str(text).map_err(|e| bad(format!("not a parts file: {e}")))?;
        labels.validate().map_err(bad)?;
        Ok(labels)
    }

    /// Checks labels against `num_parts` (itself at most [`MAX_PARTS`], checked before any
    /// conversion, so a count past `i32` cannot wrap into a small one).
    pub fn validate(&self) -> Result<(), String> {
        if self.num_parts > MAX_PARTS {
            return Err(format!(
                "num_parts = {}: at most {MAX_PARTS} parts (MAX_PARTS)",
                self.num_parts
            ));
        }
        if let Some((i, &l)) = self
            .labels
            .iter()
            .enumerate()
            .find(|(_, &l)| l < -1 || l >= self.num_parts as i32)
        {
            return Err(format!(
                "labels[{i}] = {l} is outside -1 .. {} (num_parts {})",
                self.num_parts as i32 - 1,
                self.num_parts
            ));
        }
        if !self.confidence.is_empty() && self.confidence.len() != self.labels.len() {
            return Err(format!(
                "{} confidences for {} labels",
                self.confidence.len(),
                self.labels.len()
            ));
        }
        Ok(())
    }

    /// Writes the JSON file (pretty-printed, the keys of the struct).
    pub fn write_json(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self).expect("labels serialise");
        r4d_fsio::write_atomic(path, (text + "\n").as_bytes()).map_err(Error::io(path))
    }

    /// Copies the scene PLY `scene` to `out` with a float `part` property (the label, -1 for
    /// static) appended to its vertices (an existing `part` property is replaced). Every other
    /// property is kept, as float.
    pub fn write_scene_ply(&self, scene: &Path, out: &Path) -> Result<()> {
        let ply = r4d_ply::read_ply(scene)?;
        if ply.count != self.labels.len() {
            return Err(Error::Input(format!(
                "{}: {} vertices for {} labels",
                scene.display(),
                ply.count,
                self.labels.len()
            )));
        }
        let part: Vec<f32> = self.labels.iter().map(|&l| l as f32).collect();
        let mut names: Vec<&str> = Vec::new();
        let mut cols: Vec<&[f32]> = Vec::new();
        for (n, c) in ply.columns.iter().filter(|(n, _)| n != "part") {
            names.push(n);
            cols.push(c);
        }
        names.push("part");
        cols.push(&part);
        r4d_ply::write_ply(out, &names, &cols)?;
        Ok(())
    }

    /// A link that simulates every labelled Gaussian, in scene order, in world coordinates.
    pub fn identity_link(&self) -> SimLink {
        let mut l = SimLink::identity(self.labels.len());
        l.simulated = (0..self.labels.len() as u32)
            .filter(|&i| self.labels[i as usize] >= 0)
            .collect();
        l
    }

    /// The part of every particle: simulated Gaussian `link.simulated[s]` gives particle `s`
    /// its label; filling particles take the label of the nearest labelled particle (by rest
    /// position, kd-tree). A simulated Gaussian labelled static is an error.
    pub fn particle_parts(&self, link: &SimLink, x: &[[f32; 3]]) -> Result<Vec<u32>> {
        if self.labels.len() != link.scene_gaussians {
            return Err(Error::Input(format!(
                "the parts file labels {} Gaussians, the scene has {}",
                self.labels.len(),
                link.scene_gaussians
            )));
        }
        let ns = link.simulated.len();
        if x.len() < ns {
            return Err(Error::Input(format!(
                "{} particles for {ns} simulated Gaussians",
                x.len()
            )));
        }
        let mut out = Vec::with_capacity(x.len());
        for (s, &g) in link.simulated.iter().enumerate() {
            let l = self.labels[g as usize];
            if l < 0 {
                return Err(Error::Input(format!(
                    "Gaussian {g} (particle {s}) is simulated but labelled static (-1)"
                )));
            }
            out.push(l as u32);
        }
        if x.len() > ns {
            if ns == 0 {
                return Err(Error::Input(
                    "filling particles but no labelled particle to copy a label from".into(),
                ));
            }
            let pts: Vec<[f64; 3]> = x[..ns].iter().map(|p| p.map(|v| v as f64)).collect();
            let tree: kiddo::ImmutableKdTree<f64, 3> = kiddo::ImmutableKdTree::new_from_slice(&pts);
            for p in &x[ns..] {
                let nn = tree.nearest_one::<kiddo::SquaredEuclidean>(&p.map(|v| v as f64));
                out.push(out[nn.item as usize]);
            }
        }
        Ok(out)
    }
}

/// The display colour of a label (RGB in [0, 1]): matplotlib's tab10 palette without its
/// grey for parts `0, 1, ...` (cycling after nine), dark grey for static (-1).
pub fn part_colour(label: i32) -> [f32; 3] {
    const TAB: [[u8; 3]; 9] = [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [188, 189, 34],
        [23, 190, 207],
    ];
    if label < 0 {
        return [0.35; 3];
    }
    TAB[label as usize % TAB.len()].map(|c| c as f32 / 255.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("r4d_segment_labels_{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join(name)
    }

    #[test]
    fn json_and_ply_round_trip() {
        let l = PartLabels::new(
            vec!["a".into(), "b".into()],
            vec![0, -1, 1, 1],
            vec![0.9, 0.5, 0.8, 0.7],
        );
        assert_eq!(l.counts, vec![1, 2]);
        let j = tmp("parts.json");
        l.write_json(&j).unwrap();
        assert_eq!(PartLabels::load(&j).unwrap(), l);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&j).unwrap()).unwrap();
        for key in ["num_parts", "class_names", "labels", "confidence", "counts"] {
            assert!(v.get(key).is_some(), "{key}");
        }
        let scene = tmp("scene.ply");
        let xs = [0.0f32, 1.0, 2.0, 3.0];
        r4d_ply::write_ply(&scene, &["x", "part"], &[&xs, &[5.0; 4]]).unwrap();
        let out = tmp("scene_parts.ply");
        l.write_scene_ply(&scene, &out).unwrap();
        let back = PartLabels::load(&out).unwrap();
        assert_eq!(back.labels, l.labels);
        assert_eq!(back.num_parts, 2);
        let ply = r4d_ply::read_ply(&out).unwrap();
        assert_eq!(ply.get("x").unwrap(), &xs);
        assert_eq!(ply.columns.len(), 2);
    }

    #[test]
    fn bad_files_name_the_file() {
        let j = tmp("bad_parts.json");
        std::fs::write(&j, r#"{"num_parts": 1, "labels": [0, 2]}"#).unwrap();
        let e = PartLabels::load(&j).unwrap_err().to_string();
        assert!(
            e.contains("bad_parts.json") && e.contains("labels[1] = 2"),
            "{e}"
        );
        std::fs::write(&j, "{").unwrap();
        let e = PartLabels::load(&j).unwrap_err().to_string();
        assert!(
            e.contains("bad_parts.json") && e.contains("not a parts file"),
            "{e}"
        );
        let p = tmp("no_part.ply");
        r4d_ply::write_ply(&p, &["x"], &[&[0.0]]).unwrap();
        let e = PartLabels::load(&p).unwrap_err().to_string();
        assert!(e.contains("no_part.ply") && e.contains("'part'"), "{e}");
        let p = tmp("frac_part.ply");
        r4d_ply::write_ply(&p, &["x", "part"], &[&[0.0], &[0.5]]).unwrap();
        let e = PartLabels::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("frac_part.ply") && e.contains("not an integer"),
            "{e}"
        );
    }

    #[test]
    fn filling_particles_take_the_nearest_label() {
        let l = PartLabels::new(vec!["a".into(), "b".into()], vec![0, -1, 1], vec![1.0; 3]);
        let link = l.identity_link();
        assert_eq!(link.simulated, vec![0, 2]);
        let x = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.1, 0.0, 0.0],
            [0.8, 0.0, 0.0],
        ];
        assert_eq!(l.particle_parts(&link, &x).unwrap(), vec![0, 1, 0, 1]);
        let e = l.particle_parts(&link, &x[..1]).unwrap_err().to_string();
        assert!(e.contains("1 particles for 2"), "{e}");
    }
}
