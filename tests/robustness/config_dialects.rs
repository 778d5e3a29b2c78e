//! One validation per concept: the project's TOML, PhysGaussian's JSON (`--physgaussian`) and
//! the preprocessing keys `r4d prepare` reads are decoded under the same rules (a key twice, an
//! unknown key at any depth, a document that is not a table: errors naming the key, with the
//! closest known key) and their values go through one validator (the same limits and
//! messages). Each class is checked through the commands, before any work.

use std::path::{Path, PathBuf};
use std::process::Command;

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .unwrap()
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_dialects_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// Runs `r4d args`, expects a failure whose message contains every needle and no output.
fn refused(args: &[&str], out: &Path, needles: &[&str]) -> String {
    let o = r4d(args);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(!o.status.success(), "{args:?} was accepted: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: '{n}' not in: {err}");
    }
    assert!(
        !out.exists() || std::fs::read_dir(out).unwrap().next().is_none(),
        "{args:?} wrote into {}",
        out.display()
    );
    err
}

const TOML: &str = "[domain]\nn_grid = 16\n[time]\nsubstep_dt = 1e-4\nframes = 1\nsubsteps_per_frame = 2\n[[parts]]\nmaterial = \"jelly\"\n";
const PG: &str = r#""g": [0, 0, -9.8], "n_grid": 16, "frame_num": 1"#;

/// The same hostile value in each dialect ends in the same reason, naming the file and the
/// key as that file spells it.
#[test]
fn the_dialects_share_one_validator() {
    let d = dir("validator");
    let out = d.join("out");
    let cases: &[(&str, &str, &str, &str)] = &[
        // (TOML line in [solver], its field, PhysGaussian key-value, its key)
        (
            "grid_v_damping = 0",
            "solver.grid_v_damping",
            r#""grid_v_damping_scale": 0"#,
            "grid_v_damping_scale",
        ),
        (
            "grid_v_damping = -1",
            "solver.grid_v_damping",
            r#""grid_v_damping_scale": -1"#,
            "grid_v_damping_scale",
        ),
        (
            "rpic_damping = 2",
            "solver.rpic_damping",
            r#""rpic_damping": 2"#,
            "rpic_damping",
        ),
    ];
    for (i, (tl, tf, pj, pk)) in cases.iter().enumerate() {
        let t = d.join(format!("c{i}.toml"));
        std::fs::write(&t, format!("{TOML}[solver]\n{tl}\n")).unwrap();
        let p = d.join(format!("c{i}.json"));
        std::fs::write(&p, format!("{{{PG}, {pj}}}")).unwrap();
        let te = refused(
            &["simulate", "--config", &s(&t), "--out", &s(&out)],
            &out,
            &[&s(&t), &format!("invalid {tf} = ")],
        );
        let pe = refused(
            &[
                "simulate",
                "--physgaussian",
                "--config",
                &s(&p),
                "--out",
                &s(&out),
            ],
            &out,
            &[&s(&p), &format!("invalid {pk} = ")],
        );
        let reason = |m: &str| m.trim().rsplit(": ").next().unwrap_or("").to_string();
        assert_eq!(reason(&te), reason(&pe), "{te} / {pe}");
    }
    // Boundary conditions: a start that never comes, a negative half extent, walls thicker
    // than the grid; named by their path in each dialect.
    let bcs: &[(&str, &str, &str, &str)] = &[
        (
            "type = \"cuboid\"\npoint = [0.5, 0.5, 0.5]\nsize = [0.1, 0.1, 0.1]\nstart_time = nan",
            "boundary[0].start_time = NaN",
            r#"{"type": "cuboid", "point": [1,1,1], "size": [0.1,0.1,0.1], "velocity": [0,0,0], "start_time": 5, "end_time": 1}"#,
            "boundary_conditions[0].end_time = 1",
        ),
        (
            "type = \"particle_velocity\"\nvelocity = [0.0, 0.0, 0.0]\npoint = [0.5, 0.5, 0.5]\nsize = [0.1, -0.1, 0.1]",
            "boundary[0].size[1] = -0.1",
            r#"{"type": "enforce_particle_translation", "velocity": [0,0,0], "point": [1,1,1], "size": [0.1,-0.1,0.1], "start_time": 0, "end_time": 1}"#,
            "boundary_conditions[0].size[1] = -0.1",
        ),
        (
            "type = \"bounding_box\"\nlayers = 4294967295",
            "boundary[0].layers = 4294967295",
            r#"{"type": "particle_impulse", "force": [0,0,1], "num_dt": 0}"#,
            "boundary_conditions[0].num_dt = 0",
        ),
    ];
    for (i, (tb, tn, pb, pn)) in bcs.iter().enumerate() {
        let t = d.join(format!("b{i}.toml"));
        std::fs::write(&t, format!("{TOML}[[boundary]]\n{tb}\n")).unwrap();
        refused(
            &["simulate", "--config", &s(&t), "--out", &s(&out)],
            &out,
            &[&s(&t), tn],
        );
        let p = d.join(format!("b{i}.json"));
        std::fs::write(&p, format!("{{{PG}, \"boundary_conditions\": [{pb}]}}")).unwrap();
        refused(
            &[
                "simulate",
                "--physgaussian",
                "--config",
                &s(&p),
                "--out",
                &s(&out),
            ],
            &out,
            &[&s(&p), pn],
        );
    }
}

/// Keys: a key twice, a typo at any depth, an unknown name, a document that is not a table.
#[test]
fn keys_are_strict_in_every_dialect() {
    let d = dir("keys");
    let out = d.join("out");
    let toml_cases: &[(&str, &[&str])] = &[
        ("[domain]\nn_grid = 16\nn_grid = 32\n", &["duplicate key"]),
        ("[solver]\ngravty = [0.0, 0.0, 0.0]\n", &["`solver.gravty`", "did you mean `gravity`?"]),
        (
            "[[shapes]]\nkind = \"box\"\nmin = [0.4, 0.4, 0.4]\nmax = [0.6, 0.6, 0.6]\nper_cel = 2\n",
            &["`shapes[0].per_cel`", "`per_cell`?"],
        ),
        ("[[boundary]]\ntype = \"bounding_bx\"\n", &["`bounding_bx`", "`bounding_box`?"]),
    ];
    for (i, (extra, needles)) in toml_cases.iter().enumerate() {
        let t = d.join(format!("k{i}.toml"));
        std::fs::write(&t, format!("{TOML}{extra}")).unwrap();
        let mut n = vec![s(&t)];
        n.extend(needles.iter().map(|x| x.to_string()));
        let n: Vec<&str> = n.iter().map(String::as_str).collect();
        refused(
            &["simulate", "--config", &s(&t), "--out", &s(&out)],
            &out,
            &n,
        );
    }
    let j = d.join("arr.json");
    std::fs::write(&j, "[]").unwrap();
    refused(
        &["simulate", "--config", &s(&j), "--out", &s(&out)],
        &out,
        &["arr.json", "expected a table of keys"],
    );
    let pg_cases: &[(&str, &[&str])] = &[
        (r#", "E": 1e5, "E": 2e5"#, &["duplicate key `E`"]),
        (r#", "materal": "metal""#, &["`materal`", "`material`?"]),
        (
            r#", "material": "rubber""#,
            &["unknown value `rubber` of `material`"],
        ),
        (
            r#", "boundary_conditions": [{"type": "surface_collider", "point": [1,1,1], "normal": [0,0,1], "surface": "sticky", "frictin": 1}]"#,
            &["`boundary_conditions[0].frictin`", "`friction`?"],
        ),
    ];
    for (i, (extra, needles)) in pg_cases.iter().enumerate() {
        let p = d.join(format!("k{i}.json"));
        std::fs::write(&p, format!("{{{PG}{extra}}}")).unwrap();
        let mut n = vec![s(&p)];
        n.extend(needles.iter().map(|x| x.to_string()));
        let n: Vec<&str> = n.iter().map(String::as_str).collect();
        refused(
            &[
                "simulate",
                "--physgaussian",
                "--config",
                &s(&p),
                "--out",
                &s(&out),
            ],
            &out,
            &n,
        );
        // `r4d prepare` reads the same file under the same key rules (its own keys only
        // where the value is the simulator's).
        if i < 2 {
            refused(
                &[
                    "prepare",
                    "--scene",
                    "/nonexistent.ply",
                    "--config",
                    &s(&p),
                    "--out",
                    &s(&out),
                ],
                &out,
                &n,
            );
        }
    }
    let p = d.join("fill.json");
    std::fs::write(
        &p,
        format!("{{{PG}, \"particle_filling\": {{\"n_gird\": 32}}}}"),
    )
    .unwrap();
    refused(
        &[
            "prepare",
            "--scene",
            "/nonexistent.ply",
            "--config",
            &s(&p),
            "--out",
            &s(&out),
        ],
        &out,
        &["fill.json", "`particle_filling.n_gird`", "`n_grid`?"],
    );
}

/// `simulate --particles P` takes its particles from the flag: a config without shapes or
/// `particles` is then complete (and without the flag the message says how to give them).
#[test]
fn particles_from_the_flag_complete_a_config_without_shapes() {
    let d = dir("particles");
    let t = d.join("noshapes.toml");
    std::fs::write(&t, TOML).unwrap();
    let ply = d.join("p.ply");
    let xs = [0.45f32, 0.5, 0.55];
    r4d_mpm::ply::write_ply(&ply, &["x", "y", "z"], &[&xs, &xs, &xs]).unwrap();
    let out = d.join("out");
    let o = r4d(&[
        "simulate",
        "--config",
        &s(&t),
        "--particles",
        &s(&ply),
        "--out",
        &s(&out),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(out.join("frame_0001.ply").exists());
    let out2 = d.join("out2");
    refused(
        &["simulate", "--config", &s(&t), "--out", &s(&out2)],
        &out2,
        &["noshapes.toml", "--particles"],
    );
}
