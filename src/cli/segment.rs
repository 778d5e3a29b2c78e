//! `r4d segment`: lift 2D segmentation masks onto a scene's Gaussians (part labels for
//! `r4d fit --parts`).

use anyhow::{bail, Context, Result};
use r4d_backend_cpu::CpuBackend;
use r4d_segment::label_map::label_map;
use r4d_segment::lift::{lift_with_progress, LiftConfig};
use r4d_segment::smooth::{smooth_lifted, SmoothConfig};
use r4d_segment::{part_colour, MaskDir, MaskSource, Par, PartLabels};
use r4d_splat::{load_cameras, Gaussians, RenderSettings, Renderer, SplatRenderer};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `r4d segment`.
#[derive(clap::Args, Debug)]
pub struct SegmentArgs {
    /// The static 3DGS scene (INRIA PLY).
    #[arg(long)]
    scene: PathBuf,
    /// Cameras of the masks (r4d/reference JSON, INRIA cameras.json, nerfstudio
    /// transforms.json, COLMAP text); the rasterize mode comes from the file when it has one.
    #[arg(long)]
    cameras: PathBuf,
    /// Mask folder: one mask per camera, named after the camera's image (or its index):
    /// NAME.png (label map: 0 background, k part k-1), NAME.npy (M x H x W probabilities) or
    /// NAME/CLASS.png or NAME/CLASS.npy (one probability map per class); optional
    /// classes.json (see docs/cli/segment.md).
    #[arg(long)]
    masks: PathBuf,
    /// Output parts file (JSON). Beside it: the scene with a `part` property (same name,
    /// .ply) and a render of the labels from each camera next to its mask (NAME_views/).
    #[arg(long)]
    out: PathBuf,
    /// Neighbours of the KNN smoothing in 3D (1: keep the raw lift's labels).
    #[arg(long, default_value_t = 16)]
    k: usize,
    /// Softmax temperature over the normalised class weights (smaller: more confident), in
    /// [1e-6, 1e6].
    #[arg(long, default_value_t = 0.1, value_parser = super::numeric::f64_in(1e-6, 1e6))]
    temperature: f64,
    /// Label clusters with fewer Gaussians are relabelled by their surroundings (default:
    /// k).
    #[arg(long)]
    min_cluster: Option<usize>,
    /// Rounds of label propagation over the KNN graph (1: one plain vote; more fill larger
    /// holes in the lift but let big parts creep into thin ones).
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u32).range(1..=100))]
    rounds: u32,
    /// A Gaussian with mixed evidence seen with less than this compositing weight (pixel
    /// equivalents, over all views) gets proportionally less confidence, so that the KNN pass
    /// decides it from its well-seen neighbours (0: off; at most 1e9).
    #[arg(long, default_value_t = 4.0, value_parser = super::numeric::f64_in(0.0, 1e9))]
    full_visibility: f64,
    /// Weight, in [0, 1], of a view whose own verdict on a Gaussian is background, relative
    /// to views that see a part there (a view whose mask misses part of a part outvotes less
    /// of the views that show it; where all views agree nothing changes).
    #[arg(long, default_value_t = 0.25, value_parser = super::numeric::f64_in(0.0, 1.0))]
    background_weight: f64,
    /// Merge threshold of the smooth-surface regions (graph segmentation of the KNN graph
    /// that ends at creases) whose summed evidence is a prior on which part their Gaussians
    /// are: a thin part most views' masks erase keeps its label where its whole surface
    /// says so (0: off; larger: bigger regions; at most 1e6).
    #[arg(long, default_value_t = 30.0, value_parser = super::numeric::f64_in(0.0, 1e6))]
    region_tau: f64,
    /// Exponent of the region prior: a Gaussian's evidence for a part is scaled by the
    /// region's evidence for it relative to the region's strongest part, to this power, in
    /// [0, 64] (0: off).
    #[arg(long, default_value_t = 4.0, value_parser = super::numeric::f64_in(0.0, 64.0))]
    region_power: f64,
    /// Exponent of the region prior on the static scene, one-sided: where a region's
    /// strongest part outweighs the static scene in it, its Gaussians' static evidence is
    /// scaled by their ratio to this power (a part's rim that eroded masks give to the
    /// background keeps its part); regions the static scene dominates are left alone; in
    /// [0, 64] (0: off).
    #[arg(long, default_value_t = 2.0, value_parser = super::numeric::f64_in(0.0, 64.0))]
    region_static_power: f64,
    /// Strength, in [0, 1], of the appearance term of the region prior: a region's evidence
    /// for a part is scaled by 1 - S + S x (how well its Gaussians' base colours fit that
    /// part's robust colour model), so colour can overturn at most a 1 / (1 - S) lead of
    /// the masks (parts of one colour, or colours no part has, change nothing; 0: off).
    #[arg(long, default_value_t = 0.8, value_parser = super::numeric::f64_in(0.0, 1.0))]
    appearance: f64,
    /// Do not scale a view's votes by the share of the Gaussian's drawn footprint that is
    /// the Gaussian itself (edge-on Gaussians then vote with their whole blurred line).
    #[arg(long)]
    no_footprint_trust: bool,
    /// How the views are combined: confusion (each view gets a confusion matrix estimated
    /// against the other views, and its labels count by what its record says they are
    /// worth: a view that erodes a thin part away or calls one part another loses its say
    /// on that part) or sum (every pixel's vote summed over the views).
    #[arg(long, value_enum, default_value_t = Vote::Confusion)]
    vote: Vote,
    /// The lift as it was before visibility-aware voting (sum of alpha T times the mask over
    /// every view and pixel); overrides the four options above.
    #[arg(long)]
    classic: bool,
}

/// `--vote`.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum Vote {
    /// Per-view confusion matrices (Dawid-Skene, one round).
    Confusion,
    /// Summed pixel votes.
    Sum,
}

const Y0: f32 = 0.282_094_8;

/// Runs `r4d segment`.
pub fn run(a: SegmentArgs) -> Result<()> {
    if a.k == 0 {
        bail!("--k 0: use --k 1 for no smoothing");
    }
    // The float options' ranges are checked when the command line is parsed (numeric.rs).
    if a.out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"))
    {
        bail!(
            "--out {}: name the JSON parts file (the scene PLY with the part property is written beside it)",
            a.out.display()
        );
    }
    let views_stem = a
        .out
        .file_stem()
        .map_or("parts".into(), |s| s.to_string_lossy().into_owned());
    super::paths::Io::new()
        .input("--scene", &a.scene)
        .input("--cameras", &a.cameras)
        .input("--masks", &a.masks)
        .output("--out", &a.out)
        .output(
            "--out (its labelled scene copy)",
            &a.out.with_extension("ply"),
        )
        .output(
            "--out (its label renders)",
            &a.out.with_file_name(format!("{views_stem}_views")),
        )
        .check()?;
    let t0 = Instant::now();
    let g = r4d_splat::ply::read_gaussians(&a.scene)?;
    let set = load_cameras(&a.cameras)?;
    let mut masks = MaskDir::open(&a.masks, &set.cameras)?;
    let m = masks.class_names().len();
    eprintln!(
        "{}: {} Gaussians; {} views; {m} part(s): {}",
        a.scene.display(),
        g.len(),
        set.cameras.len(),
        masks.class_names().join(", ")
    );
    let base = if a.classic {
        LiftConfig::classic()
    } else {
        LiftConfig {
            full_visibility: a.full_visibility as f32,
            footprint_trust: !a.no_footprint_trust,
            background_weight: a.background_weight as f32,
            ..Default::default()
        }
    };
    let lift_cfg = LiftConfig {
        vote: match (a.classic, a.vote) {
            (true, _) => base.vote,
            (false, Vote::Confusion) => r4d_segment::ViewVote::Confusion,
            (false, Vote::Sum) => r4d_segment::ViewVote::Sum,
        },
        temperature: a.temperature as f32,
        mode: set.mode.unwrap_or_default(),
        par: Par::Rayon,
        ..base
    };
    let n_views = set.cameras.len();
    let lifted = lift_with_progress(&g, &set.cameras, &mut masks, &lift_cfg, |v| {
        eprintln!("  lifted view {}/{n_views}", v + 1)
    })?;
    let t_lift = t0.elapsed().as_secs_f64();
    let (labels, confidence) = if a.k > 1 {
        let cfg = SmoothConfig {
            k: a.k,
            min_cluster: a.min_cluster.unwrap_or(a.k),
            rounds: a.rounds,
            region_tau: a.region_tau as f32,
            region_power: a.region_power as f32,
            region_static_power: a.region_static_power as f32,
            appearance: a.appearance as f32,
            ..Default::default()
        };
        smooth_lifted(&g, &lifted, lift_cfg.temperature, &cfg)?
    } else {
        (lifted.labels.clone(), lifted.confidence.clone())
    };
    let changed = labels
        .iter()
        .zip(&lifted.labels)
        .filter(|(x, y)| x != y)
        .count();
    let parts = PartLabels::new(masks.class_names().to_vec(), labels, confidence);
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    parts.write_json(&a.out)?;
    let ply = a.out.with_extension("ply");
    parts.write_scene_ply(&a.scene, &ply)?;
    let stem = a
        .out
        .file_stem()
        .map_or("parts".into(), |s| s.to_string_lossy().into_owned());
    let views = a.out.with_file_name(format!("{stem}_views"));
    let shares = write_views(&g, &parts, &set, &mut masks, &views)?;
    let stat = parts.labels.iter().filter(|&&l| l < 0).count();
    eprintln!(
        "lift {t_lift:.1} s ({} Gaussians seen by no view); KNN (k {}) changed {changed} label(s); total {:.1} s",
        lifted.unobserved(),
        a.k,
        t0.elapsed().as_secs_f64()
    );
    for (k, name) in parts.class_names.iter().enumerate() {
        let idx: Vec<usize> = (0..parts.labels.len())
            .filter(|&i| parts.labels[i] == k as i32)
            .collect();
        let mean_conf =
            idx.iter().map(|&i| parts.confidence[i] as f64).sum::<f64>() / idx.len().max(1) as f64;
        let mut views: Vec<u16> = idx.iter().map(|&i| lifted.views[i]).collect();
        views.sort_unstable();
        let median_views = views.get(views.len() / 2).copied().unwrap_or(0);
        eprintln!(
            "  part {k} ({name}): {} Gaussians, mean confidence {mean_conf:.2}, seen by {median_views} view(s) (median)",
            parts.counts[k]
        );
        if median_views < 2 {
            eprintln!(
                "  warning: part {k} ({name}) is seen by fewer than two views: its labels rest on one view's mask; add views that show it"
            );
        }
    }
    eprintln!("  static (-1): {stat} Gaussians");
    let shares: Vec<String> = shares.iter().map(|s| format!("{:.1}", 100.0 * s)).collect();
    eprintln!(
        "  pixels where the drawn labels differ from the mask, per view (%): {}",
        shares.join(" ")
    );
    let mut sorted = lifted.view_disagreement.clone();
    sorted.sort_by(f32::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    for (v, d) in lifted.view_disagreement.iter().enumerate() {
        if *d > 0.05 && *d > 3.0 * median {
            eprintln!(
                "  warning: view {v} ({}) disagrees with the other views on {:.0}% of the Gaussians it sees clearly (median of the views {:.0}%): check its mask",
                set.cameras[v].name,
                100.0 * d,
                100.0 * median
            );
        }
    }
    println!(
        "wrote {}, {} and {}",
        a.out.display(),
        ply.display(),
        views.display()
    );
    Ok(())
}

/// For every camera: the Gaussians rendered in their part colours (static grey) on the left,
/// the mask's classes in the same colours in the middle (ignored pixels black), and on the
/// right the disagreement map: black where the labels drawn by the Gaussians
/// ([`r4d_segment::label_map::label_map`]) agree with the mask, the mask's colour where they
/// differ (ignored pixels dark blue). Returns the disagreeing share of each view's pixels.
fn write_views(
    g: &Gaussians,
    parts: &PartLabels,
    set: &r4d_splat::CameraSet,
    masks: &mut MaskDir,
    dir: &Path,
) -> Result<Vec<f64>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut coloured = g.clone();
    coloured.sh_degree = 0;
    coloured.sh = parts
        .labels
        .iter()
        .flat_map(|&l| part_colour(l).map(|c| (c - 0.5) / Y0))
        .collect();
    let settings = RenderSettings {
        background: [0.05; 3],
        mode: set.mode.unwrap_or_default(),
    };
    let m = parts.num_parts;
    let mut r = SplatRenderer::new(CpuBackend::default());
    let mut shares = Vec::with_capacity(set.cameras.len());
    for (v, cam) in set.cameras.iter().enumerate() {
        let img = r.render(&coloured, None, cam, &settings)?;
        let mask = masks.mask(v, cam)?;
        let drawn = label_map(g, cam, &parts.labels, m, settings.mode);
        let (w, h) = (cam.width, cam.height);
        let mut out = image::RgbImage::new(3 * w, h);
        let mut differ = 0usize;
        let to_u8 = |c: f32| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
        for j in 0..h {
            for i in 0..w {
                let k = (j * w + i) as usize;
                let c = &img.rgb[3 * k..3 * k + 3];
                out.put_pixel(i, j, image::Rgb([to_u8(c[0]), to_u8(c[1]), to_u8(c[2])]));
                let ml = mask.argmax(i, j, m);
                let mc = ml.map_or([0.0; 3], part_colour);
                out.put_pixel(w + i, j, image::Rgb(mc.map(to_u8)));
                let d = match ml {
                    None => [0.05, 0.05, 0.3],
                    Some(l) if l + 1 == drawn[k] as i32 => [0.0; 3],
                    Some(_) => {
                        differ += 1;
                        mc
                    }
                };
                out.put_pixel(2 * w + i, j, image::Rgb(d.map(to_u8)));
            }
        }
        shares.push(differ as f64 / (w as f64 * h as f64));
        let path = dir.join(format!("view_{v:04}.png"));
        let mut bytes = Vec::new();
        out.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .and_then(|_| r4d_fsio::write_atomic(&path, &bytes).map_err(image::ImageError::IoError))
        .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(shares)
}
