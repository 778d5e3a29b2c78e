//! `r4d ablate` and `r4d merge`: the paper's ablations (Tables 4-7), and its main tables over
//! a list of scenes (`--study main`), as one runner sharded for a cluster's scheduler.
//!
//! A study is a fixed, ordered list of variants of the fit settings. Each variant is fitted
//! with `r4d fit` and measured with `r4d eval`, each in its own process (so its peak memory is
//! its own) and its own run folder; a variant whose run folder already holds `eval.json` for
//! the same settings is not run again, and one interrupted mid-fit continues with `r4d fit
//! --resume`, so a killed ablation loses at most the variant in progress. `--shard I/N` (I in
//! 0..N) runs the variants whose index is `I mod N` and writes `OUT/shard-I-of-N/`; `r4d merge
//! OUT` checks that the shards present cover every variant exactly once and writes
//! `OUT/ablation.json`, the same file an unsharded run writes.

use anyhow::{bail, Context, Result};
use r4d_loss::{Ablation, DmsWeights};
use resonance4d::video_fit::report::write_json;
use resonance4d::video_fit::{FitConfig, Granularity};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// The ablation studies of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Study {
    /// Tables 2-3: the fit as configured (one variant), for a list of scenes.
    Main,
    /// Table 4: L1, SSIM, L1+FFT, SSIM+FFT.
    Loss,
    /// Table 5: Latin-hypercube initialisation vs the config's start.
    Init,
    /// Table 6: one parameter set per particle, per object, per part.
    Granularity,
    /// Table 7: density free vs fixed.
    Density,
}

impl Study {
    /// The name on the command line and in the JSON files (clap's value name).
    fn name(self) -> String {
        clap::ValueEnum::to_possible_value(&self)
            .map(|v| v.get_name().to_string())
            .unwrap_or_default()
    }

    fn parse(s: &str) -> Option<Study> {
        clap::ValueEnum::from_str(s, false).ok()
    }
}

/// One variant: its label, its folder name and its settings.
struct Variant {
    label: &'static str,
    slug: &'static str,
    cfg: FitConfig,
}

/// The variants of `study` from the base settings `base` (whose free parameters per part are
/// `free`, names as in FIT.toml).
fn variants(study: Study, base: &FitConfig, free: &[Vec<String>]) -> Vec<Variant> {
    let with = |label, slug, f: &dyn Fn(&mut FitConfig)| {
        let mut cfg = base.clone();
        if cfg.strategy.is_auto() && cfg.pinned.is_none() {
            // Written out with every key: the list keeps the automatic strategy deciding.
            cfg.pinned = Some(Vec::new());
        }
        f(&mut cfg);
        Variant { label, slug, cfg }
    };
    let loss = |a: Ablation| move |c: &mut FitConfig| c.loss.weights = DmsWeights::ablation(a);
    let density = |free_density: bool| {
        move |c: &mut FitConfig| {
            c.free = None;
            c.parts = free
                .iter()
                .enumerate()
                .map(|(id, names)| {
                    let mut names: Vec<String> =
                        names.iter().filter(|n| *n != "density").cloned().collect();
                    if free_density {
                        names.push("density".into());
                    }
                    let mut p = base
                        .parts
                        .iter()
                        .find(|p| p.id == id)
                        .cloned()
                        .unwrap_or_default();
                    p.id = id;
                    if !free_density {
                        // Bounds of a parameter that is not free are refused.
                        p.bounds.retain(|n, _| !n.eq_ignore_ascii_case("density"));
                    }
                    p.free = Some(names);
                    p
                })
                .collect();
        }
    };
    match study {
        Study::Main => vec![with("Resonance4D", "main", &|_| {})],
        Study::Loss => vec![
            with("L1", "l1", &loss(Ablation::L1)),
            with("SSIM", "ssim", &loss(Ablation::Ssim)),
            with("L1+FFT", "l1_fft", &loss(Ablation::L1Fft)),
            with("SSIM+FFT", "ssim_fft", &loss(Ablation::SsimFft)),
        ],
        Study::Init => vec![
            with("config start", "config_start", &|c| {
                c.init.enabled = false;
                if c.strategy.is_auto() {
                    *c = c.clone().pin("init.enabled");
                }
            }),
            with("LHS init", "lhs", &|c| c.init.enabled = true),
        ],
        Study::Granularity => vec![
            with("particle", "particle", &|c| {
                c.granularity = Granularity::Particle
            }),
            with("object", "object", &|c| c.granularity = Granularity::Object),
            with("part", "part", &|c| c.granularity = Granularity::Part),
        ],
        Study::Density => vec![
            with("density fixed", "density_fixed", &density(false)),
            with("density free", "density_free", &density(true)),
        ],
    }
}

/// `--shard I/N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Shard {
    pub(crate) i: usize,
    pub(crate) n: usize,
}

pub(crate) fn parse_shard(s: &str) -> Result<Shard> {
    let bad = || {
        anyhow::anyhow!(
            "--shard {s}: expected I/N with 0 <= I < N (e.g. 0/4 .. 3/4; Slurm: $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT)"
        )
    };
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (usize, usize) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if !shard_ok(i, n) {
        return Err(bad());
    }
    Ok(Shard { i, n })
}

/// The most shards a run is split into.
const MAX_SHARDS: usize = 100_000;

/// The rule of `--shard I/N` and of the `shard-I-of-N` folders: `0 <= I < N <= 100000`.
fn shard_ok(i: usize, n: usize) -> bool {
    n >= 1 && i < n && n <= MAX_SHARDS
}

fn shard_dir(out: &Path, s: Shard) -> PathBuf {
    out.join(format!("shard-{}-of-{}", s.i, s.n))
}

/// Arguments of `r4d ablate`.
#[derive(clap::Args, Debug)]
pub struct AblateArgs {
    /// A dataset folder (as `r4d fit --dataset`); repeatable: every variant runs on every
    /// scene, and the work items (scene x variant) are what `--shard` splits.
    #[arg(long, required = true)]
    dataset: Vec<PathBuf>,
    /// Which table: main (Tables 2-3: the fit as configured, per scene), loss (4), init (5),
    /// granularity (6), density (7).
    #[arg(long, value_enum)]
    study: Study,
    /// Base fit settings (FIT.toml); each variant changes only what it ablates.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output folder: run folders, per-variant eval.json, ablation.json.
    #[arg(long)]
    out: PathBuf,
    /// Run only the variants of shard I of N (index mod N = I) into OUT/shard-I-of-N/.
    #[arg(long)]
    shard: Option<String>,
    /// Physics config (as `r4d fit --sim`).
    #[arg(long)]
    sim: Option<PathBuf>,
    /// Fit only the views of these cameras (as `r4d fit --camera`; repeatable).
    #[arg(long = "camera", value_name = "NAME|INDEX")]
    camera: Vec<String>,
    /// LPIPS weights for `r4d eval` (repeatable).
    #[arg(long = "lpips-weights", value_name = "FILE")]
    lpips_weights: Vec<PathBuf>,
}

/// Arguments of `r4d merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The output folder of the sharded `r4d ablate` runs.
    out: PathBuf,
}

fn r4d(args: &[String]) -> Result<()> {
    let exe = std::env::current_exe().context("locating the r4d executable")?;
    // The child's report goes to our stderr: stdout carries only the ablation table.
    let st = std::process::Command::new(&exe)
        .args(args)
        .stdout(std::process::Stdio::from(std::io::stderr()))
        .status()
        .with_context(|| format!("running {} {}", exe.display(), args.join(" ")))?;
    if !st.success() {
        bail!("`r4d {}` failed ({st})", args.join(" "));
    }
    Ok(())
}

fn read_json(path: &Path) -> Result<Value> {
    let text = r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES)
        .with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))
}

/// The file beside a variant's run folder `dir` with this suffix (`DIR.variant.json`,
/// `DIR.fit.toml`): the variant's settings live outside the fit's run folder, which holds
/// only what `r4d fit` and `r4d eval` write.
fn beside(dir: &Path, suffix: &str) -> PathBuf {
    let mut name = dir.file_name().unwrap_or_default().to_os_string();
    name.push(suffix);
    dir.with_file_name(name)
}

/// Fits and evaluates one variant in `dir` (reusing what a previous run finished), and
/// returns its row.
fn run_variant(
    a: &AblateArgs,
    dataset: &Path,
    scene: &str,
    v: &Variant,
    dir: &Path,
) -> Result<Value> {
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    let settings = json!({ "variant": v.slug, "dataset": dataset, "sim": a.sim, "camera": a.camera, "config": v.cfg });
    let marker = beside(dir, ".variant.json");
    let same = marker.is_file() && read_json(&marker)? == settings;
    if !same {
        // Another variant's or older settings: start this variant afresh (its run folder
        // lies inside the ablation's output folder and holds only the earlier fit).
        if dir.exists() {
            std::fs::remove_dir_all(dir)
                .with_context(|| format!("removing the earlier run {}", dir.display()))?;
        }
        write_json(&marker, &settings)?;
    }
    let d = |p: &Path| p.display().to_string();
    if !(same && dir.join("eval.json").is_file()) {
        if !(same && dir.join("params.json").is_file()) {
            if same
                && dir.join("checkpoint.json").is_file()
                && dir.join("invocation.json").is_file()
            {
                eprintln!("ablate: {} resumes", v.label);
                r4d(&["fit".into(), "--resume".into(), d(dir)])?;
            } else {
                // A fit killed before its first checkpoint starts over in an empty folder.
                if dir.exists() {
                    std::fs::remove_dir_all(dir)
                        .with_context(|| format!("removing {}", dir.display()))?;
                }
                let toml_path = beside(dir, ".fit.toml");
                let text = toml::to_string(&v.cfg).context("writing the variant's FIT.toml")?;
                r4d_fsio::write_atomic(&toml_path, text.as_bytes())
                    .with_context(|| format!("writing {}", toml_path.display()))?;
                let mut args: Vec<String> = vec![
                    "fit".into(),
                    "--dataset".into(),
                    d(dataset),
                    "--config".into(),
                    d(&toml_path),
                    "--out".into(),
                    d(dir),
                ];
                if let Some(s) = &a.sim {
                    args.extend(["--sim".into(), d(s)]);
                }
                for c in &a.camera {
                    args.extend(["--camera".into(), c.clone()]);
                }
                eprintln!("ablate: fitting {}", v.label);
                r4d(&args)?;
            }
        }
        let mut args: Vec<String> = vec!["eval".into(), d(dir)];
        for w in &a.lpips_weights {
            args.extend(["--lpips-weights".into(), d(w)]);
        }
        r4d(&args)?;
    }
    let ev = read_json(&dir.join("eval.json"))?;
    let params = read_json(&dir.join("params.json"))?;
    let mut row =
        json!({ "scene": scene, "variant": v.label, "slug": v.slug, "params": params["parts"] });
    for (k, _) in METRICS {
        row[*k] = ev[*k].clone();
    }
    // Written by an earlier process (possibly an earlier run): checked like a shard's rows.
    check_row(&row).with_context(|| {
        format!(
            "{} or {}: not what `r4d eval` and `r4d fit` write",
            dir.join("eval.json").display(),
            dir.join("params.json").display()
        )
    })?;
    Ok(row)
}

/// The range a metric of a row may take.
#[derive(Clone, Copy)]
enum Range {
    /// `[0, 1]` (MS-SSIM, F-score).
    Unit,
    /// Finite and `>= 0` (distances).
    NonNegative,
    /// Finite (PSNR, LPIPS).
    Finite,
}

/// The metrics of a row (as `eval.json` names them) and their ranges; each may also be
/// null (not measured, or PSNR of identical frames: +inf).
const METRICS: &[(&str, Range)] = &[
    ("ms_ssim", Range::Unit),
    ("ms_ssim_small_window", Range::Unit),
    ("psnr", Range::Finite),
    ("psnr_video", Range::Finite),
    ("lpips_alex", Range::Finite),
    ("lpips_vgg", Range::Finite),
    ("chamfer", Range::NonNegative),
    ("hd95", Range::NonNegative),
    ("f_score", Range::Unit),
];

/// Checks a row of an ablation table: names are strings, every metric null or a number in
/// its range, every part's parameters those of a valid material (finite, physical).
fn check_row(row: &Value) -> Result<()> {
    for k in ["scene", "variant", "slug"] {
        if !row[k].is_string() {
            bail!("'{k}' is {}, not a name", row[k]);
        }
    }
    for (k, range) in METRICS {
        let v = &row[*k];
        if v.is_null() {
            continue;
        }
        let x = v
            .as_f64()
            .with_context(|| format!("'{k}' is {v}, not a number"))?;
        let ok = match range {
            Range::Unit => (0.0..=1.0).contains(&x),
            Range::NonNegative => x.is_finite() && x >= 0.0,
            Range::Finite => x.is_finite(),
        };
        if !ok {
            bail!(
                "'{k}' = {x} is outside {}",
                match range {
                    Range::Unit => "[0, 1]",
                    Range::NonNegative => "[0, inf) (finite)",
                    Range::Finite => "the finite numbers",
                }
            );
        }
    }
    let parts = row["params"]
        .as_array()
        .with_context(|| format!("'params' is {}, not a list of parts", row["params"]))?;
    for (i, p) in parts.iter().enumerate() {
        let rec: resonance4d::fit_trajectory::PartRecord = serde_json::from_value(p.clone())
            .with_context(|| format!("params[{i}]: not a part's parameters"))?;
        let material: r4d_mpm::Material =
            serde_json::from_value(Value::String(rec.material.clone()))
                .with_context(|| format!("params[{i}]: unknown material '{}'", rec.material))?;
        rec.apply_to(&r4d_mpm::PartParams::new(material))
            .validate(&format!("params[{i}]"))?;
    }
    Ok(())
}

/// Free parameter names per part of the dataset's config under `cfg`.
fn free_names(a: &AblateArgs, dataset: &Path, cfg: &FitConfig) -> Result<Vec<Vec<String>>> {
    let opts = r4d_datasets::LoadOptions {
        sim: a.sim.clone(),
        ..Default::default()
    };
    let ds = r4d_datasets::load(dataset, &opts)?;
    let kinds = cfg.free_kinds(&ds.config.parts)?;
    Ok(kinds
        .iter()
        .map(|ks| ks.iter().map(|k| k.name().to_string()).collect())
        .collect())
}

/// The scene names of the datasets (folder names; must differ).
fn scene_names(datasets: &[PathBuf]) -> Result<Vec<String>> {
    let mut names: Vec<String> = Vec::new();
    for d in datasets {
        let n = d
            .canonicalize()
            .unwrap_or_else(|_| d.clone())
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("scene")
            .to_string();
        if names.contains(&n) {
            bail!("--dataset {}: another --dataset is also named '{n}' (scenes are told apart by folder name)", d.display());
        }
        names.push(n);
    }
    Ok(names)
}

/// Runs `r4d ablate`.
pub fn run(a: AblateArgs) -> Result<()> {
    let shard = a.shard.as_deref().map(parse_shard).transpose()?;
    let base = match &a.config {
        Some(p) => FitConfig::load(p)?,
        None => FitConfig::default(),
    };
    let scenes = scene_names(&a.dataset)?;
    // Work items in order: scene-major, then the study's variants.
    let mut items: Vec<(usize, Variant)> = Vec::new();
    for (j, d) in a.dataset.iter().enumerate() {
        let free = free_names(&a, d, &base)?;
        items.extend(variants(a.study, &base, &free).into_iter().map(|v| (j, v)));
    }
    let mine: Vec<usize> = (0..items.len())
        .filter(|k| shard.is_none_or(|s| k % s.n == s.i))
        .collect();
    let root = match shard {
        Some(s) => shard_dir(&a.out, s),
        None => a.out.join("runs"),
    };
    // Checked before any long work: the folders can be made.
    std::fs::create_dir_all(&root).with_context(|| format!("creating {}", root.display()))?;
    let mut rows = Vec::new();
    for (n, &k) in mine.iter().enumerate() {
        let (j, v) = &items[k];
        eprintln!(
            "ablate {}: {}/{}: {} on {}",
            a.study.name(),
            n + 1,
            mine.len(),
            v.label,
            scenes[*j]
        );
        let dir = root.join(&scenes[*j]).join(v.slug);
        rows.push(run_variant(&a, &a.dataset[*j], &scenes[*j], v, &dir)?);
    }
    let key = |k: usize| format!("{}/{}", scenes[items[k].0], items[k].1.slug);
    match shard {
        Some(s) => {
            let rec = json!({
                "study": a.study.name(),
                "shard": s.i,
                "of": s.n,
                "scenes": scenes,
                "items": mine.iter().map(|&k| key(k)).collect::<Vec<_>>(),
                "rows": rows,
            });
            write_json(&shard_dir(&a.out, s).join("shard.json"), &rec)?;
            eprintln!(
                "shard {}/{} done ({} run(s)); combine the shards with `r4d merge {}`",
                s.i,
                s.n,
                mine.len(),
                a.out.display()
            );
        }
        None => {
            let table = json!({ "study": a.study.name(), "scenes": scenes, "rows": rows });
            write_json(&a.out.join("ablation.json"), &table)?;
            println!("{}", print_table(&table));
        }
    }
    Ok(())
}

/// The shard folders of `out`: one split, no gap, every shard finished; with their records.
fn collect_shards(out: &Path) -> Result<Vec<(Shard, PathBuf, Value)>> {
    let mut shards: Vec<(Shard, PathBuf)> = Vec::new();
    let rd = std::fs::read_dir(out).with_context(|| format!("reading {}", out.display()))?;
    for e in rd.filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().to_string();
        let Some(rest) = name.strip_prefix("shard-") else {
            continue;
        };
        let Some((i, n)) = rest.split_once("-of-") else {
            continue;
        };
        if let (Ok(i), Ok(n)) = (i.parse::<usize>(), n.parse::<usize>()) {
            if !shard_ok(i, n) {
                bail!(
                    "{}: not a shard of a split: shard folders are shard-I-of-N with 0 <= I < N <= {MAX_SHARDS} (the rule of --shard I/N)",
                    e.path().display()
                );
            }
            shards.push((Shard { i, n }, e.path()));
        }
    }
    if shards.is_empty() {
        bail!(
            "{}: no shard-I-of-N folders (run `r4d ablate --shard I/N` or `r4d fit --shard I/N` with --out {} first)",
            out.display(),
            out.display()
        );
    }
    shards.sort_by_key(|s| (s.0.n, s.0.i));
    let n = shards[0].0.n;
    if let Some(other) = shards.iter().find(|s| s.0.n != n) {
        bail!(
            "{} and {} split the work differently (N = {n} and {}): their work overlaps; keep one split",
            shards[0].1.display(),
            other.1.display(),
            other.0.n
        );
    }
    let have: Vec<usize> = shards.iter().map(|s| s.0.i).collect();
    let missing: Vec<String> = (0..n)
        .filter(|i| !have.contains(i))
        .map(|i| format!("shard-{i}-of-{n}"))
        .collect();
    if !missing.is_empty() {
        bail!(
            "{}: missing {} (a gap: run shard I/{n} for each)",
            out.display(),
            missing.join(", ")
        );
    }
    let mut recs = Vec::new();
    let mut kind: Option<String> = None;
    for (s, dir) in shards {
        let path = dir.join("shard.json");
        if !path.is_file() {
            bail!(
                "{}: shard {}/{} has not finished (no shard.json)",
                dir.display(),
                s.i,
                s.n
            );
        }
        let rec = read_json(&path)?;
        if rec["shard"].as_u64() != Some(s.i as u64) || rec["of"].as_u64() != Some(n as u64) {
            bail!(
                "{}: records shard {}/{}, its folder says {}/{n}",
                path.display(),
                rec["shard"],
                rec["of"],
                s.i
            );
        }
        let k = rec["kind"].as_str().unwrap_or("ablation").to_string();
        match &kind {
            None => kind = Some(k),
            Some(x) if *x != k => {
                bail!("{}: a shard of {k}, the others are of {x}", path.display())
            }
            _ => {}
        }
        recs.push((s, path, rec));
    }
    Ok(recs)
}

/// Runs `r4d merge`: ablation shards into `ablation.json`, initialisation shards (`r4d fit
/// --shard`) into the run's `init.json` and `checkpoint.json`.
pub fn run_merge(a: MergeArgs) -> Result<()> {
    let recs = collect_shards(&a.out)?;
    if recs[0].2["kind"] == "init" {
        return merge_init(&a.out, &recs);
    }
    let n = recs[0].0.n;
    let (study, scenes) = (&recs[0].2["study"], &recs[0].2["scenes"]);
    let mut by_key: Vec<(String, Value)> = Vec::new();
    for (_, path, rec) in &recs {
        if rec["study"] != *study || rec["scenes"] != *scenes {
            bail!(
                "{}: study {} on scenes {}, the first shard ran {study} on {scenes}: the shards are of different runs",
                path.display(),
                rec["study"],
                rec["scenes"]
            );
        }
        let rows = rec["rows"]
            .as_array()
            .with_context(|| format!("{}: 'rows' is not a list", path.display()))?;
        for (j, row) in rows.iter().enumerate() {
            check_row(row).with_context(|| format!("{}: rows[{j}]", path.display()))?;
            let key = format!(
                "{}/{}",
                row["scene"].as_str().unwrap_or_default(),
                row["slug"].as_str().unwrap_or_default()
            );
            if by_key.iter().any(|(x, _)| *x == key) {
                bail!(
                    "{}: '{key}' is also in another shard (an overlap)",
                    path.display()
                );
            }
            by_key.push((key, row.clone()));
        }
    }
    let study = study.as_str().unwrap_or_default().to_string();
    let st =
        Study::parse(&study).with_context(|| format!("unknown study '{study}' in the shards"))?;
    let scene_list: Vec<String> =
        serde_json::from_value(scenes.clone()).context("shard.json: bad 'scenes'")?;
    // Scene-major, then the study's variant order (settings do not change the names).
    let order: Vec<String> = scene_list
        .iter()
        .flat_map(|sc| {
            variants(st, &FitConfig::default(), &[])
                .into_iter()
                .map(move |v| format!("{sc}/{}", v.slug))
        })
        .collect();
    let mut rows = Vec::new();
    for (i, key) in order.iter().enumerate() {
        let Some((_, row)) = by_key.iter().find(|(k, _)| k == key) else {
            bail!(
                "{}: '{key}' is in no shard (it belongs to shard-{}-of-{n}, which did not run it)",
                a.out.display(),
                i % n
            );
        };
        rows.push(row.clone());
    }
    if let Some((key, _)) = by_key.iter().find(|(k, _)| !order.contains(k)) {
        bail!(
            "{}: '{key}' is not part of the '{study}' study on these scenes",
            a.out.display()
        );
    }
    let table = json!({ "study": study, "scenes": scene_list, "rows": rows });
    write_json(&a.out.join("ablation.json"), &table)?;
    println!("{}", print_table(&table));
    Ok(())
}

/// Initialisation shards: every candidate exactly once, ranked as one unsharded
/// initialisation ranks them; writes `init.json` and a `checkpoint.json` after the
/// initialisation, so `r4d fit --resume OUT` optimises from the best candidate.
fn merge_init(out: &Path, recs: &[(Shard, PathBuf, Value)]) -> Result<()> {
    use r4d_optim::{Candidate, InitOutcome};
    let first = &recs[0].2;
    let n = recs[0].0.n;
    let total = first["total"].as_u64().context("shard.json: no 'total'")?;
    // The candidates the shards hold bound what is allocated (a hand-edited `total` must not).
    let held: usize = recs
        .iter()
        .map(|r| r.2["candidates"].as_array().map_or(0, |c| c.len()))
        .sum();
    if total != held as u64 {
        bail!(
            "{}: the shards hold {held} candidates, their shard.json files say {total} (a gap or an overlap)",
            out.display()
        );
    }
    let total = held;
    let mut slots: Vec<Option<Candidate>> = (0..total).map(|_| None).collect();
    for (s, path, rec) in recs {
        for key in ["names", "total", "top_k", "fit_config", "fingerprint"] {
            if rec[key] != first[key] {
                bail!(
                    "{}: '{key}' differs from {}'s: the shards are of different fits",
                    path.display(),
                    recs[0].1.display()
                );
            }
        }
        let cands: Vec<Candidate> = serde_json::from_value(rec["candidates"].clone())
            .with_context(|| format!("{}: bad candidates", path.display()))?;
        for c in cands {
            if c.index >= total || c.index % n != s.i {
                bail!(
                    "{}: candidate #{} does not belong to shard {}/{n} of {total}",
                    path.display(),
                    c.index,
                    s.i
                );
            }
            if slots[c.index].is_some() {
                bail!(
                    "{}: candidate #{} is also in another shard (an overlap)",
                    path.display(),
                    c.index
                );
            }
            let i = c.index;
            slots[i] = Some(c);
        }
    }
    let missing: Vec<String> = slots
        .iter()
        .enumerate()
        .filter(|(_, c)| c.is_none())
        .map(|(i, _)| format!("#{i} (shard {})", i % n))
        .collect();
    if !missing.is_empty() {
        bail!(
            "{}: candidates {} were not evaluated (a gap)",
            out.display(),
            missing.join(", ")
        );
    }
    let candidates: Vec<Candidate> = slots.into_iter().flatten().collect();
    let names: Vec<String> = serde_json::from_value(first["names"].clone())
        .with_context(|| format!("{}: 'names' is not a list of names", recs[0].1.display()))?;
    let cfg: FitConfig =
        serde_json::from_value(first["fit_config"].clone()).with_context(|| {
            format!(
                "{}: 'fit_config' is not a fit configuration",
                recs[0].1.display()
            )
        })?;
    // The bounds the shards sampled in (`bounds`, one `[lo, hi]` per name); a record
    // without them is checked against the settings' bounds.
    let bounds: Option<Vec<(f64, f64)>> = match first.get("bounds") {
        None => None,
        Some(b) => {
            let b: Vec<(f64, f64)> = serde_json::from_value(b.clone()).with_context(|| {
                format!(
                    "{}: 'bounds' is not a list of [lo, hi] pairs",
                    recs[0].1.display()
                )
            })?;
            if b.len() != names.len() {
                bail!(
                    "{}: {} bounds for {} names",
                    recs[0].1.display(),
                    b.len(),
                    names.len()
                );
            }
            Some(b)
        }
    };
    for c in &candidates {
        let path = &recs[c.index % n].1;
        check_candidate(c, &names, bounds.as_deref(), &cfg)
            .with_context(|| format!("{}: candidate #{}", path.display(), c.index))?;
    }
    let top_k = match first["top_k"].as_u64() {
        Some(k) if k >= 1 => k as usize,
        _ => bail!(
            "{}: 'top_k' is {}, not a count >= 1",
            recs[0].1.display(),
            first["top_k"]
        ),
    };
    let outcome = InitOutcome::from_candidates(candidates, top_k)
        .map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
    write_json(
        &out.join("init.json"),
        &json!({ "names": names, "outcome": outcome }),
    )?;
    let fingerprint: String = serde_json::from_value(first["fingerprint"].clone())
        .context("shard.json: no 'fingerprint' (a shard written by an older r4d: run it again)")?;
    let mut state = resonance4d::video_fit::FitState::new(names.clone(), fingerprint);
    state.init = Some(outcome.clone());
    super::checkpoint::write(&out.join("checkpoint.json"), &state)?;
    let best = &outcome.candidates[outcome.ranking[0]];
    let vals: Vec<String> = names
        .iter()
        .zip(&best.theta)
        .map(|(k, v)| format!("{k}={v:.4e}"))
        .collect();
    println!(
        "{total} candidates from {n} shard(s); best #{} {}: {}\ncontinue with `r4d fit --resume {}`",
        best.index,
        super::run_hooks::score_text(best.score.unwrap_or(f64::NAN)),
        vals.join(" "),
        out.display()
    );
    Ok(())
}

/// Checks an initialisation candidate of a shard: its score (MS-SSIM in [0, 1], or with
/// `[init] score = "loss"` a negated loss, at most 0; none: a failed evaluation), one value per name, each finite and within `bounds` (the shard's
/// search space), else within the bounds the fit settings give the parameter it names
/// (`part{P}.{kind}` or `object.{kind}`) by default.
fn check_candidate(
    c: &r4d_optim::Candidate,
    names: &[String],
    bounds: Option<&[(f64, f64)]>,
    cfg: &FitConfig,
) -> Result<()> {
    if let Some(s) = c.score {
        match cfg.init.score {
            r4d_optim::video::InitScore::MsSsim if !(0.0..=1.0).contains(&s) => {
                bail!("score (MS-SSIM) {s} is outside [0, 1]")
            }
            r4d_optim::video::InitScore::Loss if !(s.is_finite() && s <= 0.0) => {
                bail!("score (negated loss) {s} is not a finite number <= 0")
            }
            _ => {}
        }
    }
    if c.theta.len() != names.len() {
        bail!(
            "{} values for the {} parameters ({})",
            c.theta.len(),
            names.len(),
            names.join(", ")
        );
    }
    for (i, (name, &v)) in names.iter().zip(&c.theta).enumerate() {
        let (part, kind) = match name.split_once('.') {
            Some(("object", k)) => (None, k),
            Some((p, k)) => match p.strip_prefix("part").map(str::parse::<usize>) {
                Some(Ok(p)) => (Some(p), k),
                _ => bail!("'{name}' is not a parameter name (partP.KIND or object.KIND)"),
            },
            None => bail!("'{name}' is not a parameter name (partP.KIND or object.KIND)"),
        };
        let kind =
            r4d_optim::ParamKind::parse(kind).map_err(|e| anyhow::anyhow!("'{name}': {e}"))?;
        let (lo, hi) = match bounds {
            Some(b) => b[i],
            None => cfg.bounds(&[], part, kind),
        };
        // The candidates are sampled in log space: allow the rounding of exp(ln x).
        let slack = 1e-9;
        if !(v.is_finite() && v >= lo * (1.0 - slack) && v <= hi * (1.0 + slack)) {
            bail!("{name} = {v} is outside its bounds [{lo}, {hi}]");
        }
    }
    Ok(())
}

/// The ablation table: one row per variant with the paper's columns.
fn print_table(t: &Value) -> String {
    let f = super::eval::num;
    let rows = t["rows"].as_array().cloned().unwrap_or_default();
    let traj = rows.iter().any(|r| !r["chamfer"].is_null());
    let mut s = format!(
        "study: {}\n{:<14} {:<16} {:>9} {:>8} {:>11}",
        t["study"].as_str().unwrap_or(""),
        "scene",
        "variant",
        "MS-SSIM^",
        "PSNR^",
        "LPIPS_"
    );
    if traj {
        s.push_str(&format!(
            " {:>12} {:>12} {:>9}",
            "Chamfer_", "HD95_", "F-score^"
        ));
    }
    for r in &rows {
        let ms = super::eval::ms_ssim_cell(r);
        let psnr = super::eval::psnr_cell(r);
        let lp = if r["lpips_alex"].is_null() {
            f(&r["lpips_vgg"], 4)
        } else {
            f(&r["lpips_alex"], 4)
        };
        s.push_str(&format!(
            "\n{:<14} {:<16} {:>9} {:>8} {:>11}",
            r["scene"].as_str().unwrap_or(""),
            r["variant"].as_str().unwrap_or(""),
            ms,
            psnr,
            lp
        ));
        if traj {
            let e = |v: &Value| v.as_f64().map_or("n/a".into(), |x| format!("{x:.4e}"));
            s.push_str(&format!(
                " {:>12} {:>12} {:>9}",
                e(&r["chamfer"]),
                e(&r["hd95"]),
                f(&r["f_score"], 4)
            ));
        }
    }
    s.push_str(
        "\n(^ higher is better, _ lower is better; * small-window MS-SSIM; + whole-video PSNR)",
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_and_partition() {
        assert_eq!(parse_shard("1/3").unwrap(), Shard { i: 1, n: 3 });
        for bad in ["3/3", "1", "a/2", "0/0", "-1/2"] {
            assert!(parse_shard(bad).is_err(), "{bad}");
        }
        let v = variants(Study::Granularity, &FitConfig::default(), &[]);
        let mut seen = vec![0; v.len()];
        for i in 0..2 {
            for k in (0..v.len()).filter(|k| k % 2 == i) {
                seen[k] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
    }

    #[test]
    fn variants_change_only_what_they_ablate() {
        let base = FitConfig::default();
        let free = vec![vec!["E".to_string(), "density".to_string()]];
        let v = variants(Study::Density, &base, &free);
        assert_eq!(
            v[0].cfg.parts[0].free.as_deref(),
            Some(&["E".to_string()][..])
        );
        assert_eq!(
            v[1].cfg.parts[0].free.as_deref(),
            Some(&["E".to_string(), "density".to_string()][..])
        );
        let l = variants(Study::Loss, &base, &free);
        assert_eq!(l[0].cfg.loss.weights, DmsWeights::ablation(Ablation::L1));
        assert_eq!(l[0].cfg.loss.spectral, base.loss.spectral);
        assert_eq!(l[0].cfg.iters, base.iters);
    }
}
