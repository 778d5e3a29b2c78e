//! `r4d render`: render a 3DGS scene (optionally deformed by simulated frames) to PNG/.npy,
//! or a whole simulated sequence to PNGs plus an animated GIF.

use super::npy::write_npy_f32;
use super::BackendKind;
use anyhow::{bail, Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use r4d_backend_cpu::CpuBackend;
use r4d_splat::reference::ReferenceSplat;
use r4d_splat::{
    load_cameras, Deformation, Gaussians, Image, RasterizeMode, RenderSettings, Renderer, SimLink,
    SplatRenderer,
};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Rasterize mode flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// gsplat's classic mode.
    Classic,
    /// gsplat's antialiased mode (opacity compensation).
    Antialiased,
}

/// Arguments of `r4d render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The Gaussians: an INRIA 3DGS PLY file.
    #[arg(long)]
    scene: PathBuf,
    /// Cameras: r4d/reference JSON, INRIA cameras.json, nerfstudio transforms.json, or a
    /// COLMAP text folder (cameras.txt + images.txt).
    #[arg(long)]
    camera: PathBuf,
    /// Which camera of the file.
    #[arg(long, default_value_t = 0)]
    camera_index: usize,
    /// Output: a PNG file (single render) or, with --frames, a folder.
    #[arg(long)]
    out: PathBuf,
    /// Also write the colour as float32 H x W x 3 .npy (row 0 at the top).
    #[arg(long)]
    out_raw: Option<PathBuf>,
    /// With --frames: OUT holds an earlier `r4d render --frames` output; remove its files
    /// first (without this a non-empty OUT is refused).
    #[arg(long, requires = "frames")]
    overwrite: bool,
    /// Deform the scene by one simulated frame (`r4d simulate --write-f` PLY).
    #[arg(long, conflicts_with = "frames")]
    frame: Option<PathBuf>,
    /// Render every frame_NNNN.ply of a simulation folder to OUT/frame_NNNN.png plus
    /// OUT/animation.gif and OUT/animation.mp4 (H.264).
    #[arg(long)]
    frames: Option<PathBuf>,
    /// The simulation link (link.json from `r4d prepare`): simulated Gaussians and the
    /// world-to-simulation transform. Default: FRAMES/link.json or the frame's folder's
    /// link.json when present, else every Gaussian is particle i in world coordinates.
    #[arg(long)]
    link: Option<PathBuf>,
    /// Background r,g,b in [0, 1] when the camera file has none (`0.5,0.5,0.5` or
    /// `0.5 0.5 0.5`).
    #[arg(long, value_delimiter = ',', num_args = 1..=3, value_parser = super::numeric::f64_in(0.0, 1.0))]
    background: Option<Vec<f64>>,
    /// Rasterize mode when the camera file has none.
    #[arg(long, value_enum)]
    mode: Option<ModeArg>,
    /// Frames per second of the animation.
    #[arg(long, default_value_t = 24)]
    fps: u32,
    /// Renderer backend.
    #[arg(long, value_enum, default_value_t = BackendKind::Cpu)]
    backend: BackendKind,
    /// Print the GPU time of every kernel when the command ends (timestamp queries; the
    /// Vulkan backend measures it, the others say they cannot).
    #[arg(long)]
    profile: bool,
}

/// Runs the command.
pub fn run(a: RenderArgs) -> Result<()> {
    if let Some(b) = a.background.as_ref().filter(|b| b.len() != 3) {
        bail!(
            "--background: give three values r,g,b in [0, 1] (got {})",
            b.len()
        );
    }
    super::paths::Io::new()
        .input("--scene", &a.scene)
        .input("--camera", &a.camera)
        .input_opt("--frame", a.frame.as_deref())
        .input_opt("--frames", a.frames.as_deref())
        .input_opt("--link", a.link.as_deref())
        .output("--out", &a.out)
        .output_opt("--out-raw", a.out_raw.as_deref())
        .check()?;
    let scene = r4d_splat::ply::read_gaussians(&a.scene)?;
    let set = load_cameras(&a.camera)?;
    let Some(cam) = set.cameras.get(a.camera_index).cloned() else {
        bail!(
            "{}: camera index {} but the file has {} cameras",
            a.camera.display(),
            a.camera_index,
            set.cameras.len()
        );
    };
    let settings = RenderSettings {
        background: match (set.background, &a.background) {
            (Some(b), _) => b,
            // Three values in [0, 1], checked when the command line is parsed.
            (None, Some(b)) => match b[..] {
                [r, g, bl] => [r as f32, g as f32, bl as f32],
                _ => bail!("--background: give three values r,g,b (got {})", b.len()),
            },
            (None, None) => [0.0; 3],
        },
        mode: match (set.mode, a.mode) {
            (Some(m), _) => m,
            (None, Some(ModeArg::Antialiased)) => RasterizeMode::Antialiased,
            _ => RasterizeMode::Classic,
        },
    };
    settings
        .validate("--background")
        .map_err(|e| anyhow::anyhow!(e))?;
    let vulkan = matches!(a.backend, BackendKind::Vulkan);
    let mut _profile = super::profile::Profile::unsupported(a.backend.name(), a.profile && !vulkan);
    let mut renderer: Box<dyn Renderer> = match a.backend {
        BackendKind::Cpu => Box::new(SplatRenderer::new(CpuBackend::default())),
        BackendKind::Reference => Box::new(SplatRenderer::new(ReferenceSplat)),
        BackendKind::Wgpu => {
            let ctx = r4d_backend_wgpu::WgpuContext::new()?;
            eprintln!("wgpu adapter: {} ({:?})", ctx.info.name, ctx.info.backend);
            Box::new(SplatRenderer::new(r4d_backend_wgpu::WgpuBackend::new(
                std::sync::Arc::new(ctx),
            )))
        }
        BackendKind::Vulkan => {
            let e = r4d_backend_vulkan::VulkanEngine::new()
                .map_err(|e| anyhow::anyhow!("--backend vulkan: {e}"))?;
            eprintln!("vulkan device: {}", e.device_name());
            _profile = super::profile::Profile::on_vulkan(&e, a.profile)?;
            Box::new(SplatRenderer::new(r4d_backend_vulkan::VulkanBackend::new(
                e,
            )))
        }
    };
    let link_default = |dir: Option<&Path>| -> Result<Option<SimLink>> {
        let path = match (&a.link, dir) {
            (Some(p), _) => p.clone(),
            (None, Some(d)) if d.join("link.json").exists() => d.join("link.json"),
            _ => return Ok(None),
        };
        Ok(Some(SimLink::load(&path)?))
    };
    if let Some(dir) = &a.frames {
        let link = link_default(Some(dir))?;
        return render_sequence(&a, dir, &scene, link, &cam, &settings, renderer.as_mut());
    }
    let deform = match &a.frame {
        Some(f) => {
            let link = link_default(f.parent())?;
            Some(frame_deformation(f, &scene, link.as_ref())?)
        }
        None => None,
    };
    let img = renderer.render(&scene, deform.as_ref(), &cam, &settings)?;
    write_png(&a.out, &img)?;
    if let Some(raw) = &a.out_raw {
        write_npy_f32(raw, &[img.height as usize, img.width as usize, 3], &img.rgb)?;
    }
    eprintln!(
        "rendered {} Gaussians from camera '{}' ({}x{}) to {}",
        scene.len(),
        cam.name,
        cam.width,
        cam.height,
        a.out.display()
    );
    Ok(())
}

/// Reads one simulated frame and builds the deformation of `scene`.
fn frame_deformation(
    path: &Path,
    scene: &Gaussians,
    link: Option<&SimLink>,
) -> Result<Deformation> {
    let ply = r4d_mpm::ply::read_ply(path)?;
    let col = |n: &str| {
        ply.get(n)
            .with_context(|| format!("{}: no property '{n}'", path.display()))
    };
    let (x, y, z) = (col("x")?, col("y")?, col("z")?);
    let pos: Vec<[f32; 3]> = (0..ply.count).map(|i| [x[i], y[i], z[i]]).collect();
    const F: [&str; 9] = [
        "f00", "f01", "f02", "f10", "f11", "f12", "f20", "f21", "f22",
    ];
    let f = if F.iter().all(|n| ply.get(n).is_some()) {
        let cols: Vec<&[f32]> = F.iter().map(|n| ply.get(n).unwrap()).collect();
        Some(
            (0..ply.count)
                .map(|i| [0, 1, 2].map(|r| [0, 1, 2].map(|c| cols[3 * r + c][i])))
                .collect::<Vec<_>>(),
        )
    } else {
        None
    };
    let identity;
    let link = match link {
        Some(l) => l,
        None => {
            identity = SimLink::identity(scene.len());
            &identity
        }
    };
    Ok(link.deformation(scene, &pos, f.as_deref(), &path.display().to_string())?)
}

fn render_sequence(
    a: &RenderArgs,
    dir: &Path,
    scene: &Gaussians,
    link: Option<SimLink>,
    cam: &r4d_splat::Camera,
    settings: &RenderSettings,
    renderer: &mut dyn Renderer,
) -> Result<()> {
    let frames: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("frame_") && n.ends_with(".ply"))
        })
        .collect();
    let frames = r4d_fsio::seq::frame_sequence(frames)?;
    if frames.is_empty() {
        bail!("{}: no frame_NNNN.ply files", dir.display());
    }
    super::paths::claim_dir(
        "--out",
        &a.out,
        "render",
        &["animation.gif", "animation.mp4"],
        super::paths::Existing::from_flags(false, a.overwrite),
    )?;
    let bar = ProgressBar::new(frames.len() as u64);
    if !std::io::stderr().is_terminal() {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template("rendering {bar:40} {pos}/{len} frames, eta {eta}")
            .expect("template"),
    );
    let gif_path = a.out.join("animation.gif");
    let mut gif_file = r4d_fsio::AtomicFile::create(&gif_path)
        .with_context(|| format!("creating {}", gif_path.display()))?;
    let mut gif = image::codecs::gif::GifEncoder::new_with_speed(&mut gif_file, 10);
    gif.set_repeat(image::codecs::gif::Repeat::Infinite)?;
    let delay = image::Delay::from_numer_denom_ms(1000, a.fps.max(1));
    let mp4_path = a.out.join("animation.mp4");
    let mut mp4 = match r4d_video::Mp4Writer::create(
        &mp4_path,
        cam.width as usize,
        cam.height as usize,
        f64::from(a.fps.max(1)),
    ) {
        Ok(w) => Some(w),
        Err(e) => {
            eprintln!("note: no animation.mp4: {e}");
            None
        }
    };
    for f in &frames {
        let d = frame_deformation(f, scene, link.as_ref())?;
        let img = renderer.render(scene, Some(&d), cam, settings)?;
        let stem = f.file_stem().and_then(|s| s.to_str()).unwrap_or("frame");
        write_png(&a.out.join(format!("{stem}.png")), &img)?;
        let rgba = to_rgba(&img);
        gif.encode_frame(image::Frame::from_parts(rgba, 0, 0, delay))?;
        if let Some(m) = mp4.as_mut() {
            m.push(&img.rgb)?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    // Dropping the encoder writes the GIF trailer; then the file replaces the old one.
    drop(gif);
    gif_file
        .commit()
        .with_context(|| format!("writing {}", gif_path.display()))?;
    if let Some(m) = mp4 {
        m.finish()?;
    }
    eprintln!(
        "rendered {} frames to {} (PNG per frame + animation.gif + animation.mp4)",
        frames.len(),
        a.out.display()
    );
    Ok(())
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn to_rgba(img: &Image) -> image::RgbaImage {
    let mut out = image::RgbaImage::new(img.width, img.height);
    for (k, px) in out.pixels_mut().enumerate() {
        let c = &img.rgb[3 * k..3 * k + 3];
        *px = image::Rgba([to_u8(c[0]), to_u8(c[1]), to_u8(c[2]), 255]);
    }
    out
}

/// Writes an 8-bit PNG (values clipped to [0, 1] and rounded).
fn write_png(path: &Path, img: &Image) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let buf: Vec<u8> = img.rgb.iter().map(|&v| to_u8(v)).collect();
    let mut bytes = Vec::new();
    image::write_buffer_with_format(
        &mut std::io::Cursor::new(&mut bytes),
        &buf,
        img.width,
        img.height,
        image::ColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .with_context(|| format!("encoding {}", path.display()))?;
    r4d_fsio::write_atomic(path, &bytes).with_context(|| format!("writing {}", path.display()))
}
