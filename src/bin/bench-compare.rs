//! `bench-compare`: fails when a criterion benchmark got slower than a saved baseline.
//!
//! Criterion keeps, for every benchmark, a directory under `target/criterion/` (the id with
//! `/` as nested directories, e.g. `substep_cpu/10648/` for `substep/cpu/10648`) holding one
//! sub-directory per saved run: `new/` (the latest run), `base/` (criterion's default baseline)
//! and one per `--save-baseline NAME`, each with an `estimates.json`. This tool walks that
//! tree, and for every benchmark that has both `<baseline>/estimates.json` and
//! `new/estimates.json` compares the median's `point_estimate` (nanoseconds per iteration).
//! It prints one row per benchmark (id, baseline, new, change) and exits with
//!
//! * 0 when no benchmark is slower than the baseline by more than `--threshold` percent;
//! * 1 when at least one is (the rows marked `REGRESSED`);
//! * 2 on an error (no criterion directory, no benchmark with that baseline, a filter matching
//!   nothing, an unreadable `estimates.json`) or bad arguments.
//!
//! Benchmarks without the baseline are counted (the first few named) and not compared. A
//! benchmark's id is `full_id` from its `new/benchmark.json` (the path relative to the
//! criterion directory when that file is missing).
//!
//! Workflow (see BENCHMARKS.md, "Catching regressions"):
//!
//! ```sh
//! git switch main
//! cargo bench --bench mpm -- --save-baseline main     # writes */main/ (and */new/)
//! git switch my-branch
//! cargo bench --bench mpm -- --baseline main          # writes */new/, keeps */main/
//! cargo run --release --bin bench-compare -- --baseline main --threshold 10
//! ```
//!
//! Options: `--baseline NAME` (default `main`), `--threshold PCT` (default 10),
//! `--criterion-dir DIR` (default `target/criterion`), `--filter SUBSTRING` (compare only the
//! benchmarks whose id contains it). A benchmark not re-run after the baseline was saved keeps
//! the `new/` of that run, so it compares equal (0%).
//!
//! Baselines kept in the repository: `--save FILE` writes the medians of the latest runs
//! (`new/`) to a JSON file (`{"format": "r4d-bench-baseline/1", "machine": ...,
//! "medians_ns": {id: ns}}`) instead of comparing; `--against FILE` compares the latest runs
//! with such a file instead of a criterion baseline, so a regression against the committed
//! figures shows in one command after `cargo bench`:
//!
//! ```sh
//! cargo bench --bench mpm --bench mpm_backward -- cpu
//! cargo run --release --bin bench-compare -- --against benches/baselines/2core-vm.json --threshold 15
//! ```

use anyhow::{bail, Context, Result};
use clap::Parser;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Command line.
#[derive(Parser, Debug, Clone)]
#[command(
    name = "bench-compare",
    about = "Compares criterion's latest results (new/) with a saved baseline; exits 1 when a \
             benchmark got slower than the threshold"
)]
struct Args {
    /// Name of the saved baseline (`cargo bench -- --save-baseline NAME`).
    #[arg(long, default_value = "main")]
    baseline: String,
    /// Largest allowed slow-down of the median, in percent.
    #[arg(long, default_value_t = 10.0)]
    threshold: f64,
    /// Criterion's output directory.
    #[arg(long, default_value = "target/criterion")]
    criterion_dir: PathBuf,
    /// Compare only the benchmarks whose id contains this substring.
    #[arg(long)]
    filter: Option<String>,
    /// Compare with the medians saved in this file (`--save`) instead of a criterion
    /// baseline.
    #[arg(long, conflicts_with = "save")]
    against: Option<PathBuf>,
    /// Write the medians of the latest runs to this file (a baseline to commit) instead of
    /// comparing.
    #[arg(long)]
    save: Option<PathBuf>,
    /// With `--save`: what the figures were measured on (written into the file).
    #[arg(long, default_value = "")]
    machine: String,
}

/// Format tag of a saved baseline file.
const BASELINE_FORMAT: &str = "r4d-bench-baseline/1";

/// Largest baseline file read (bytes).
const MAX_BASELINE_BYTES: u64 = 16 << 20;

/// Where the baseline medians come from.
enum Baseline {
    /// A criterion baseline directory name (`<bench>/<name>/estimates.json`).
    Dir(String),
    /// Medians read from a `--save` file, by benchmark id.
    File(std::collections::BTreeMap<String, f64>),
}

/// Reads a baseline file written by `--save`.
fn read_baseline_file(path: &Path) -> Result<std::collections::BTreeMap<String, f64>> {
    use std::io::Read as _;
    let f = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut text = String::new();
    f.take(MAX_BASELINE_BYTES + 1)
        .read_to_string(&mut text)
        .with_context(|| format!("reading {}", path.display()))?;
    if text.len() as u64 > MAX_BASELINE_BYTES {
        bail!(
            "{}: larger than {MAX_BASELINE_BYTES} bytes, not a baseline file",
            path.display()
        );
    }
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let format = v.get("format").and_then(|f| f.as_str()).unwrap_or("");
    if format != BASELINE_FORMAT {
        bail!(
            "{}: field 'format' is '{format}', expected '{BASELINE_FORMAT}' (write one with --save)",
            path.display()
        );
    }
    let medians = v
        .get("medians_ns")
        .and_then(|m| m.as_object())
        .with_context(|| format!("{}: no object 'medians_ns'", path.display()))?;
    let mut out = std::collections::BTreeMap::new();
    for (id, ns) in medians {
        let ns = ns
            .as_f64()
            .filter(|x| x.is_finite() && *x > 0.0)
            .with_context(|| {
                format!(
                    "{}: medians_ns['{id}'] is not a positive time in ns",
                    path.display()
                )
            })?;
        out.insert(id.clone(), ns);
    }
    Ok(out)
}

/// The medians of the latest runs as a baseline file's text.
fn baseline_file_text(report: &Report, machine: &str) -> String {
    let medians: serde_json::Map<String, serde_json::Value> = report
        .latest
        .iter()
        .map(|(id, ns)| (id.clone(), serde_json::json!(ns)))
        .collect();
    let v = serde_json::json!({
        "format": BASELINE_FORMAT,
        "machine": machine,
        "medians_ns": medians,
    });
    serde_json::to_string_pretty(&v).expect("a JSON value serialises") + "\n"
}

/// One benchmark's medians.
#[derive(Debug, Clone, PartialEq)]
struct Comparison {
    /// Criterion's benchmark id (`group/function/parameter`).
    id: String,
    /// Median of the baseline, ns per iteration.
    baseline_ns: f64,
    /// Median of the latest run, ns per iteration.
    new_ns: f64,
}

impl Comparison {
    /// Relative change of the median in percent (positive: slower).
    fn change_pct(&self) -> f64 {
        (self.new_ns / self.baseline_ns - 1.0) * 100.0
    }

    /// Slower than the baseline by more than `threshold` percent.
    fn regressed(&self, threshold: f64) -> bool {
        self.change_pct() > threshold
    }
}

/// What the walk found.
#[derive(Debug, Default)]
struct Report {
    /// Benchmarks with both the baseline and a latest run, sorted by id.
    compared: Vec<Comparison>,
    /// Ids of benchmarks (matching the filter) with a latest run but no such baseline.
    without_baseline: Vec<String>,
    /// Every latest run (matching the filter): id and median (ns), sorted by id.
    latest: Vec<(String, f64)>,
}

impl Report {
    /// The compared benchmarks slower than `threshold` percent.
    fn regressions(&self, threshold: f64) -> Vec<&Comparison> {
        self.compared
            .iter()
            .filter(|c| c.regressed(threshold))
            .collect()
    }
}

/// Reads the median's point estimate (ns) from a criterion `estimates.json`.
fn median_ns(path: &Path) -> Result<f64> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let ns = v
        .get("median")
        .and_then(|m| m.get("point_estimate"))
        .and_then(|p| p.as_f64())
        .with_context(|| format!("{}: no median.point_estimate", path.display()))?;
    if !ns.is_finite() || ns <= 0.0 {
        bail!("{}: median {ns} is not a positive time", path.display());
    }
    Ok(ns)
}

/// The benchmark id of directory `dir`: `full_id` of `new/benchmark.json`, else the path
/// relative to `root`.
fn bench_id(dir: &Path, root: &Path) -> String {
    std::fs::read_to_string(dir.join("new").join("benchmark.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v.get("full_id")?.as_str().map(str::to_string))
        .unwrap_or_else(|| {
            let rel = dir.strip_prefix(root).unwrap_or(dir);
            rel.components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join("/")
        })
}

/// Walks `dir` (criterion's `report/` directories excluded), adding every benchmark found.
fn walk(dir: &Path, root: &Path, args: &Args, base: &Baseline, out: &mut Report) -> Result<()> {
    if dir.join("new").join("estimates.json").is_file() {
        let id = bench_id(dir, root);
        if args.filter.as_ref().is_none_or(|f| id.contains(f.as_str())) {
            let new_ns = median_ns(&dir.join("new").join("estimates.json"))?;
            out.latest.push((id.clone(), new_ns));
            let baseline_ns = match base {
                Baseline::Dir(name) => {
                    let path = dir.join(name).join("estimates.json");
                    if path.is_file() {
                        Some(median_ns(&path)?)
                    } else {
                        None
                    }
                }
                Baseline::File(m) => m.get(&id).copied(),
            };
            match baseline_ns {
                Some(baseline_ns) => out.compared.push(Comparison {
                    baseline_ns,
                    new_ns,
                    id,
                }),
                None => out.without_baseline.push(id),
            }
        }
    }
    let entries = std::fs::read_dir(dir).with_context(|| format!("listing {}", dir.display()))?;
    let mut subdirs = Vec::new();
    for e in entries {
        let e = e.with_context(|| format!("listing {}", dir.display()))?;
        if e.file_type()?.is_dir() && e.file_name() != "report" {
            subdirs.push(e.path());
        }
    }
    subdirs.sort();
    for d in subdirs {
        walk(&d, root, args, base, out)?;
    }
    Ok(())
}

/// Collects the comparisons; an error when there is nothing to compare.
fn collect(args: &Args) -> Result<Report> {
    let root = &args.criterion_dir;
    if !root.is_dir() {
        bail!(
            "criterion directory {} does not exist (run `cargo bench` first, or pass \
             --criterion-dir)",
            root.display()
        );
    }
    if !args.threshold.is_finite() {
        bail!("--threshold must be a finite percentage");
    }
    let base = match &args.against {
        Some(path) => Baseline::File(read_baseline_file(path)?),
        None => Baseline::Dir(args.baseline.clone()),
    };
    let mut report = Report::default();
    walk(root, root, args, &base, &mut report)?;
    report.compared.sort_by(|a, b| a.id.cmp(&b.id));
    report.without_baseline.sort();
    report.latest.sort_by(|a, b| a.0.cmp(&b.0));
    if args.save.is_some() {
        if report.latest.is_empty() {
            bail!(
                "no criterion results{} under {} to save (run `cargo bench` first)",
                args.filter
                    .as_ref()
                    .map_or(String::new(), |f| format!(" whose id contains '{f}'")),
                root.display()
            );
        }
        return Ok(report);
    }
    if let (true, Some(path)) = (report.compared.is_empty(), &args.against) {
        bail!(
            "none of the {} latest run(s) under {} is in {} (run the benches it lists)",
            report.without_baseline.len(),
            root.display(),
            path.display()
        );
    }
    if report.compared.is_empty() {
        let scope = match &args.filter {
            Some(f) => format!(" whose id contains '{f}'"),
            None => String::new(),
        };
        if report.without_baseline.is_empty() {
            bail!(
                "no criterion results{scope} under {} (run `cargo bench` first)",
                root.display()
            );
        }
        bail!(
            "no benchmark{scope} under {} has a baseline named '{}' ({} without it; save one \
             with `cargo bench -- --save-baseline {}`)",
            root.display(),
            args.baseline,
            report.without_baseline.len(),
            args.baseline
        );
    }
    Ok(report)
}

/// A duration in ns, with a unit.
fn fmt_time(ns: f64) -> String {
    if ns >= 1e9 {
        format!("{:.3} s", ns / 1e9)
    } else if ns >= 1e6 {
        format!("{:.3} ms", ns / 1e6)
    } else if ns >= 1e3 {
        format!("{:.3} us", ns / 1e3)
    } else {
        format!("{ns:.1} ns")
    }
}

/// The table and the summary.
fn render(report: &Report, args: &Args) -> String {
    let mut s = String::new();
    let w = report
        .compared
        .iter()
        .map(|c| c.id.len())
        .max()
        .unwrap_or(0)
        .max("benchmark".len());
    let base_name = baseline_name(args);
    let base_head = format!("baseline ({base_name})");
    let bw = base_head.len().max(12);
    let _ = writeln!(
        s,
        "{:<w$}  {:>bw$}  {:>12}  {:>9}  status",
        "benchmark", base_head, "new", "change"
    );
    for c in &report.compared {
        let status = if c.regressed(args.threshold) {
            "REGRESSED"
        } else if c.change_pct() < -args.threshold {
            "faster"
        } else {
            "ok"
        };
        let _ = writeln!(
            s,
            "{:<w$}  {:>bw$}  {:>12}  {:>+8.2}%  {status}",
            c.id,
            fmt_time(c.baseline_ns),
            fmt_time(c.new_ns),
            c.change_pct()
        );
    }
    let bad = report.regressions(args.threshold);
    let _ = writeln!(
        s,
        "\n{} benchmark(s) compared against '{}': {} slower than +{}%",
        report.compared.len(),
        base_name,
        bad.len(),
        args.threshold
    );
    let missing = &report.without_baseline;
    if !missing.is_empty() {
        let shown = missing.len().min(5);
        let _ = writeln!(
            s,
            "{} benchmark(s) without baseline '{}', not compared: {}{}",
            missing.len(),
            base_name,
            missing[..shown].join(", "),
            if missing.len() > shown {
                ", ... (--filter narrows the set)"
            } else {
                ""
            }
        );
    }
    s
}

/// The baseline's name in the table: the criterion baseline or the file.
fn baseline_name(args: &Args) -> String {
    match &args.against {
        Some(p) => p.display().to_string(),
        None => args.baseline.clone(),
    }
}

/// Runs the comparison: `Ok(true)` when something regressed. With `--save`, writes the
/// baseline file instead and says so.
fn run(args: &Args) -> Result<(bool, String)> {
    let report = collect(args)?;
    if let Some(path) = &args.save {
        r4d_fsio::write_atomic(path, baseline_file_text(&report, &args.machine).as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
        return Ok((
            false,
            format!(
                "saved the medians of {} benchmark(s) to {}\n",
                report.latest.len(),
                path.display()
            ),
        ));
    }
    let text = render(&report, args);
    Ok((!report.regressions(args.threshold).is_empty(), text))
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(&args) {
        Ok((regressed, text)) => {
            print!("{text}");
            if regressed {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            }
        }
        Err(e) => {
            eprintln!("bench-compare: error: {e:#}");
            ExitCode::from(2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A fresh, empty directory under the system's temporary directory.
    fn temp_tree(name: &str) -> PathBuf {
        static N: AtomicUsize = AtomicUsize::new(0);
        let dir = std::env::temp_dir().join(format!(
            "r4d-bench-compare-{}-{}-{name}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Writes one run (`new`, `base`, a baseline name) of benchmark `id` with median `ns`, as
    /// criterion lays it out (`/` in ids become directories).
    fn put(root: &Path, id: &str, run: &str, ns: f64) {
        let dir = root.join(id).join(run);
        std::fs::create_dir_all(&dir).unwrap();
        let est = format!(
            r#"{{"mean":{{"confidence_interval":{{"confidence_level":0.95,"lower_bound":{l},"upper_bound":{u}}},"point_estimate":{m},"standard_error":1.0}},"median":{{"confidence_interval":{{"confidence_level":0.95,"lower_bound":{l},"upper_bound":{u}}},"point_estimate":{ns},"standard_error":1.0}},"median_abs_dev":null,"slope":null,"std_dev":null}}"#,
            l = ns * 0.9,
            u = ns * 1.1,
            m = ns * 1.05,
        );
        std::fs::write(dir.join("estimates.json"), est).unwrap();
        let bench = format!(
            r#"{{"group_id":"g","function_id":null,"value_str":null,"throughput":null,"full_id":"{id}","directory_name":"{id}","title":"{id}"}}"#
        );
        std::fs::write(dir.join("benchmark.json"), bench).unwrap();
    }

    fn args(root: &Path) -> Args {
        Args {
            baseline: "main".into(),
            threshold: 10.0,
            criterion_dir: root.to_path_buf(),
            filter: None,
            against: None,
            save: None,
            machine: String::new(),
        }
    }

    #[test]
    fn saved_files_are_baselines() {
        let root = temp_tree("file");
        put(&root, "substep_cpu/32768", "new", 4.0e6);
        put(&root, "adjoint_substep_cpu/backward/32768", "new", 2.0e7);
        let file = root.join("baseline.json");
        let save = Args {
            save: Some(file.clone()),
            machine: "test".into(),
            ..args(&root)
        };
        let (regressed, text) = run(&save).unwrap();
        assert!(!regressed && text.contains("2 benchmark(s)"), "{text}");
        put(&root, "substep_cpu/32768", "new", 5.0e6); // +25%
        put(&root, "splat/forward/1", "new", 1.0e6); // not in the file
        let against = Args {
            against: Some(file.clone()),
            ..args(&root)
        };
        let report = collect(&against).unwrap();
        assert_eq!(report.compared.len(), 2);
        assert_eq!(report.without_baseline, vec!["splat/forward/1".to_string()]);
        let (regressed, text) = run(&against).unwrap();
        assert!(regressed && text.contains("+25.00%  REGRESSED"), "{text}");
        // Bad files are errors naming the file and the field.
        std::fs::write(
            &file,
            r#"{"format":"r4d-bench-baseline/1","medians_ns":{"a":-1}}"#,
        )
        .unwrap();
        let e = format!("{:#}", collect(&against).unwrap_err());
        assert!(
            e.contains("medians_ns['a']") && e.contains("baseline.json"),
            "{e}"
        );
        std::fs::write(&file, r#"{"medians_ns":{}}"#).unwrap();
        let e = format!("{:#}", collect(&against).unwrap_err());
        assert!(e.contains("field 'format'"), "{e}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn within_threshold_passes() {
        let root = temp_tree("pass");
        put(&root, "substep_cpu/10648", "main", 4.0e6);
        put(&root, "substep_cpu/10648", "new", 4.3e6); // +7.5%
        put(&root, "splat/forward/100000", "main", 4.0e8);
        put(&root, "splat/forward/100000", "new", 3.0e8); // faster
        std::fs::create_dir_all(root.join("report")).unwrap();
        let report = collect(&args(&root)).unwrap();
        assert_eq!(report.compared.len(), 2);
        assert_eq!(report.compared[0].id, "splat/forward/100000");
        assert!((report.compared[1].change_pct() - 7.5).abs() < 1e-9);
        let (regressed, text) = run(&args(&root)).unwrap();
        assert!(!regressed, "{text}");
        assert!(text.contains("faster"), "{text}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn slower_than_threshold_fails_and_threshold_is_honoured() {
        let root = temp_tree("fail");
        put(&root, "adjoint_substep_cpu/backward/10648", "main", 2.0e7);
        put(&root, "adjoint_substep_cpu/backward/10648", "new", 2.5e7); // +25%
        put(&root, "adjoint_substep_cpu/forward/10648", "main", 3.0e6);
        put(&root, "adjoint_substep_cpu/forward/10648", "new", 3.0e6);
        let (regressed, text) = run(&args(&root)).unwrap();
        assert!(regressed, "{text}");
        assert!(text.contains("REGRESSED"), "{text}");
        assert!(text.contains("+25.00%"), "{text}");
        let loose = Args {
            threshold: 30.0,
            ..args(&root)
        };
        assert!(!run(&loose).unwrap().0);
        let strict = Args {
            threshold: 25.0,
            ..args(&root)
        };
        // Exactly at the threshold is not a regression.
        assert!(!run(&strict).unwrap().0);
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn filter_selects_benchmarks() {
        let root = temp_tree("filter");
        put(&root, "substep_cpu/10648", "main", 1.0e6);
        put(&root, "substep_cpu/10648", "new", 2.0e6); // +100%
        put(&root, "substep_wgpu/32768", "main", 1.0e8);
        put(&root, "substep_wgpu/32768", "new", 1.0e8);
        let only_wgpu = Args {
            filter: Some("wgpu".into()),
            ..args(&root)
        };
        let report = collect(&only_wgpu).unwrap();
        assert_eq!(report.compared.len(), 1);
        assert_eq!(report.compared[0].id, "substep_wgpu/32768");
        assert!(!run(&only_wgpu).unwrap().0);
        assert!(run(&args(&root)).unwrap().0);
        let nothing = Args {
            filter: Some("no-such-bench".into()),
            ..args(&root)
        };
        let e = collect(&nothing).unwrap_err().to_string();
        assert!(e.contains("no-such-bench"), "{e}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn other_baselines_and_missing_ones() {
        let root = temp_tree("baselines");
        // Criterion's default baseline `base` is not `main`.
        put(&root, "loss/dms", "base", 1.0e6);
        put(&root, "loss/dms", "new", 5.0e6);
        put(&root, "loss/ssim", "main", 1.0e6);
        put(&root, "loss/ssim", "new", 1.05e6);
        let report = collect(&args(&root)).unwrap();
        assert_eq!(report.compared.len(), 1);
        assert_eq!(report.without_baseline, vec!["loss/dms".to_string()]);
        let (regressed, text) = run(&args(&root)).unwrap();
        assert!(!regressed);
        assert!(
            text.contains("1 benchmark(s) without baseline 'main', not compared: loss/dms"),
            "{text}"
        );
        let base = Args {
            baseline: "base".into(),
            ..args(&root)
        };
        assert!(run(&base).unwrap().0);
        let missing = Args {
            baseline: "v0.1".into(),
            ..args(&root)
        };
        let e = format!("{:#}", collect(&missing).unwrap_err());
        assert!(e.contains("baseline named 'v0.1'"), "{e}");
        assert!(e.contains("--save-baseline v0.1"), "{e}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn missing_or_empty_directory_is_an_error() {
        let root = temp_tree("missing");
        let gone = root.join("criterion");
        let e = collect(&args(&gone)).unwrap_err().to_string();
        assert!(e.contains("does not exist"), "{e}");
        let e = collect(&args(&root)).unwrap_err().to_string();
        assert!(e.contains("no criterion results"), "{e}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn id_falls_back_to_the_path_and_bad_estimates_are_errors() {
        let root = temp_tree("fallback");
        put(&root, "a/b", "main", 1.0e3);
        put(&root, "a/b", "new", 1.0e3);
        std::fs::remove_file(root.join("a/b/new/benchmark.json")).unwrap();
        let report = collect(&args(&root)).unwrap();
        assert_eq!(report.compared[0].id, "a/b");
        std::fs::write(root.join("a/b/main/estimates.json"), "{\"mean\":{}}").unwrap();
        let e = format!("{:#}", collect(&args(&root)).unwrap_err());
        assert!(e.contains("median.point_estimate"), "{e}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn command_line_defaults() {
        let a = Args::try_parse_from(["bench-compare"]).unwrap();
        assert_eq!(a.baseline, "main");
        assert_eq!(a.threshold, 10.0);
        assert_eq!(a.criterion_dir, PathBuf::from("target/criterion"));
        assert!(a.filter.is_none());
        let a = Args::try_parse_from([
            "bench-compare",
            "--baseline",
            "v1",
            "--threshold",
            "5",
            "--filter",
            "cpu",
            "--criterion-dir",
            "/tmp/c",
        ])
        .unwrap();
        assert_eq!(
            (a.baseline.as_str(), a.threshold, a.filter.as_deref()),
            ("v1", 5.0, Some("cpu"))
        );
    }
}
