//! `r4d bench-recovery`: the recovery benchmark (see `resonance4d::demo::recovery`). Random
//! scenes of every material class, fitted with the default settings under a fixed budget;
//! per class, the fraction of the determined parameters recovered, the error distribution,
//! the wall times and the failures.
//!
//! Every scene's result is a file `OUT/scenes/CLASS-SEED.json`, written when the scene ends:
//! a run resumes (`--resume`) by skipping the scenes whose file is there, so a kill loses at
//! most the scene in progress; `--shard I/N` runs the scenes whose index is `I mod N`, and
//! shards may share `OUT` (one file per scene) or be copied together later. `OUT/bench.json`
//! holds the settings: a resumed run or a shard with other settings is refused. Every run
//! ends by writing the table of every result present (`OUT/table.md`, `OUT/summary.json`);
//! `--report` only does that.

use anyhow::{bail, Context, Result};
use resonance4d::demo::random::Class;
use resonance4d::demo::recovery::{self, BenchSettings, SceneResult};
use resonance4d::demo::Size;
use resonance4d::video_fit::report::write_json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `r4d bench-recovery`.
#[derive(clap::Args, Debug)]
pub struct BenchRecoveryArgs {
    /// Run folder: bench.json (the settings), scenes/CLASS-SEED.json (one per scene),
    /// table.md and summary.json.
    #[arg(long, default_value = "out/bench-recovery")]
    out: PathBuf,
    /// The material classes, comma-separated: jelly, metal, metal_hardening, sand, foam,
    /// plasticine, two_part (default: all).
    #[arg(long, value_delimiter = ',')]
    materials: Vec<String>,
    /// Scenes per class (seeds 0 .. N-1).
    #[arg(long, default_value_t = 12)]
    scenes: u64,
    /// The fit's wall-clock budget per scene (`4m`, `90s`; `none` for no time limit).
    #[arg(long, default_value = "4m")]
    budget: String,
    /// The fit's evaluation budget per scene (simulations), as well as or instead of
    /// --budget.
    #[arg(long)]
    evals: Option<usize>,
    /// Fit settings (a FIT.toml) instead of the defaults, for comparing settings: its
    /// `free` and `[[parts]]` must be absent (every scene fits its material's default free
    /// parameters within their default bounds); --budget and --evals replace its budget.
    #[arg(long, value_name = "FIT.toml")]
    config: Option<PathBuf>,
    /// The test-size scenes (grid 12, 10 frames, 64x48 views: seconds per scene; the CI's
    /// version, no accuracy claim).
    #[arg(long)]
    small: bool,
    /// Run only the scenes whose index (class-major, then seed) is I mod N.
    #[arg(long)]
    shard: Option<String>,
    /// OUT holds an earlier run with the same settings: run the scenes it lacks.
    #[arg(long)]
    resume: bool,
    /// Only write and print the table of the results in OUT.
    #[arg(long)]
    report: bool,
    /// Where the fits and profiles run: cpu or wgpu (the reference videos are always simulated
    /// on the CPU in f64).
    #[arg(long, value_enum, default_value_t = super::BackendKind::Cpu)]
    backend: super::BackendKind,
}

/// The most scenes per class.
const MAX_SCENES: u64 = 10_000;

/// The largest scene result read back (bytes).
const MAX_RESULT_BYTES: u64 = 4 << 20;

/// `bench.json`: the settings every scene of the run was fitted with.
#[derive(serde::Serialize, serde::Deserialize, PartialEq, Debug)]
struct BenchFile {
    /// The format's version (scenes of another version are not comparable).
    version: u32,
    /// The settings.
    settings: BenchSettings,
}

/// The version of the random scenes and of the scoring: a change to either makes earlier
/// results incomparable, and a run folder of another version is refused.
const BENCH_VERSION: u32 = 1;

/// Runs the command.
pub fn run(a: BenchRecoveryArgs) -> Result<()> {
    let classes: Vec<Class> = if a.materials.is_empty() {
        Class::ALL.to_vec()
    } else {
        a.materials
            .iter()
            .map(|m| {
                Class::parse(m).ok_or_else(|| {
                    anyhow::anyhow!(
                        "--materials '{m}': use jelly, metal, metal_hardening, sand, foam, plasticine or two_part"
                    )
                })
            })
            .collect::<Result<_>>()?
    };
    if a.scenes == 0 || a.scenes > MAX_SCENES {
        bail!("--scenes {}: must be in 1..={MAX_SCENES}", a.scenes);
    }
    let budget = match a.budget.trim() {
        "none" => None,
        b => {
            r4d_optim::video::budget::parse_duration(b)
                .map_err(|m| anyhow::anyhow!("--budget {m}"))?;
            Some(b.to_string())
        }
    };
    if a.evals == Some(0) {
        bail!("--evals 0: an evaluation budget must be at least 1");
    }
    if budget.is_none() && a.evals.is_none() {
        bail!("--budget none needs --evals N: a benchmark scene's fit must have a budget");
    }
    let fit = match &a.config {
        None => None,
        Some(p) => {
            super::paths::Io::new().input("--config", p).check()?;
            let c = r4d_optim::video::FitConfig::load(p)
                .map_err(|e| anyhow::anyhow!("--config {e}"))?;
            if c.free.is_some() || !c.parts.is_empty() {
                bail!(
                    "--config {}: `free` and [[parts]] are set; a benchmark scene fits its material's default free parameters within their default bounds",
                    p.display()
                );
            }
            Some(c)
        }
    };
    let shard = a
        .shard
        .as_deref()
        .map(super::ablate::parse_shard)
        .transpose()?;
    let strategy = fit.as_ref().map_or_else(
        || r4d_optim::video::FitConfig::default().strategy,
        |c| c.strategy,
    );
    let settings = BenchSettings {
        strategy,
        size: if a.small { Size::Small } else { Size::Full },
        budget,
        evals: a.evals,
        fit,
    };
    let scenes_dir = a.out.join("scenes");
    if a.report {
        return report(&a.out);
    }
    super::paths::Io::new().output("--out", &a.out).check()?;
    let existing = super::paths::Existing::from_flags(a.resume || shard.is_some(), false);
    super::paths::claim_dir("--out", &a.out, "bench-recovery", &["bench.json"], existing)?;
    let file = BenchFile {
        version: BENCH_VERSION,
        settings,
    };
    let bench = a.out.join("bench.json");
    if bench.is_file() {
        let old: BenchFile = read(&bench)?;
        if old != file {
            bail!(
                "{}: the run there used other settings ({}), not these ({}); use another --out",
                bench.display(),
                serde_json::to_string(&old)?,
                serde_json::to_string(&file)?
            );
        }
    } else {
        write_json(&bench, &file)?;
    }
    std::fs::create_dir_all(&scenes_dir)
        .with_context(|| format!("--out: creating {}", scenes_dir.display()))?;
    let items: Vec<(Class, u64)> = classes
        .iter()
        .flat_map(|&c| (0..a.scenes).map(move |s| (c, s)))
        .enumerate()
        .filter(|(k, _)| shard.is_none_or(|s| k % s.n == s.i))
        .map(|(_, item)| item)
        .collect();
    let todo: Vec<(Class, u64)> = items
        .iter()
        .copied()
        .filter(|&(c, s)| !scenes_dir.join(SceneResult::file_name(c, s)).is_file())
        .collect();
    eprintln!(
        "bench-recovery: {} scene(s) in this run, {} done earlier, {} to fit ({}; budget {} per scene)",
        items.len(),
        items.len() - todo.len(),
        todo.len(),
        if a.small { "small scenes" } else { "full scenes" },
        match (&file.settings.budget, file.settings.evals) {
            (Some(b), Some(e)) => format!("{b} or {e} simulations"),
            (Some(b), None) => b.clone(),
            (None, Some(e)) => format!("{e} simulations"),
            (None, None) => unreachable!("checked above"),
        }
    );
    let compute = a.backend.compute()?;
    let t0 = Instant::now();
    for (n, &(class, seed)) in todo.iter().enumerate() {
        let scene = resonance4d::demo::random::scene(class, seed, file.settings.size);
        eprintln!("[{}/{}] {}", n + 1, todo.len(), scene.spec.description);
        let r = recovery::run_scene(
            class,
            seed,
            &file.settings,
            &mut r4d_optim::video::fit::NoHooks,
            resonance4d::compute::cpu(),
            compute.clone(),
        )
        .with_context(|| format!("scene {}-{seed}", class.name()))?;
        let line = match &r.failed {
            Some(w) => format!("failed: {w}"),
            None => format!(
                "{}/{} determined parameters recovered ({}); fit {:.0} s, {} simulations{}",
                r.recovered(),
                r.determined(),
                r.params
                    .iter()
                    .map(|p| format!(
                        "{} {}{}",
                        p.name,
                        if p.kind == "friction_angle" {
                            format!("{:+.1} deg", p.fit - p.truth)
                        } else {
                            format!("{:+.1}%", 100.0 * (p.fit - p.truth) / p.truth)
                        },
                        if p.determined {
                            ""
                        } else {
                            " (not determined)"
                        }
                    ))
                    .collect::<Vec<_>>()
                    .join(", "),
                r.fit_time_s,
                r.evals,
                if r.budget_spent { ", budget spent" } else { "" }
            ),
        };
        eprintln!("    {line}");
        write_json(&scenes_dir.join(SceneResult::file_name(class, seed)), &r)?;
    }
    if !todo.is_empty() {
        eprintln!(
            "bench-recovery: {} scene(s) in {:.0} s",
            todo.len(),
            t0.elapsed().as_secs_f64()
        );
    }
    report(&a.out)
}

/// Reads a JSON file of at most [`MAX_RESULT_BYTES`].
fn read<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let bytes = r4d_fsio::read_bounded(path, MAX_RESULT_BYTES)
        .with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_slice(&bytes).with_context(|| {
        format!(
            "{}: not a bench-recovery file of this version",
            path.display()
        )
    })
}

/// Writes `table.md` and `summary.json` of every scene result in `out` and prints the table.
fn report(out: &Path) -> Result<()> {
    let dir = out.join("scenes");
    if !dir.is_dir() {
        bail!(
            "--out {}: no scenes/ folder (not a bench-recovery run, or nothing finished yet)",
            out.display()
        );
    }
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .map(|e| e.map(|e| e.path()))
        .collect::<std::io::Result<_>>()
        .with_context(|| format!("reading {}", dir.display()))?;
    paths.retain(|p| p.extension().is_some_and(|e| e == "json"));
    paths.sort();
    let mut results = Vec::with_capacity(paths.len());
    for p in &paths {
        let r: SceneResult = read(p)?;
        let expected = SceneResult::file_name(r.class, r.seed);
        if p.file_name()
            .is_none_or(|n| n.to_string_lossy() != expected)
        {
            bail!(
                "{}: holds the result of {expected}; a result file keeps the name it was written under",
                p.display()
            );
        }
        results.push(r);
    }
    let rows = recovery::table(&results);
    let md = recovery::markdown(&rows);
    r4d_fsio::write_atomic(&out.join("table.md"), md.as_bytes())
        .with_context(|| format!("writing {}", out.join("table.md").display()))?;
    write_json(
        &out.join("summary.json"),
        &serde_json::json!({ "classes": rows, "scenes": results.len() }),
    )?;
    println!("{md}");
    Ok(())
}
