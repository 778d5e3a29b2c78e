//! The readers and the float options: one hostile-input test per class, through the CLI.
//! Video inputs (range, natural order and numbering, frame sizes), `.npy` headers numpy
//! refuses, truncated ASCII PLY files and float options out of range must each end in a
//! typed error naming the file (or flag) and the value or limit: never a panic, a hang or
//! silently wrong data.

use super::hostile_options::{r4d, refused};
use std::path::{Path, PathBuf};

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_readers_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A float32 `.npy` with a raw header (padded as numpy pads it).
fn npy_raw(header: &str, values: &[f32]) -> Vec<u8> {
    let mut h = header.to_string();
    let total = 10 + h.len() + 1;
    h.push_str(&" ".repeat((64 - total % 64) % 64));
    h.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(h.as_bytes());
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

fn png(path: &Path, w: u32, h: u32, v: u8) {
    image::RgbImage::from_pixel(w, h, image::Rgb([v, v, v]))
        .save(path)
        .unwrap();
}

#[test]
fn video_values_outside_unit_range_are_refused_naming_file_and_value() {
    let d = out_dir("range");
    let ok = d.join("ok.npy");
    let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 2, 3), }";
    std::fs::write(&ok, npy_raw(header, &[0.5; 24])).unwrap();
    let mut vals = [0.5f32; 24];
    // Frame 1, row 0, column 1, green: 255 (an 8-bit value not divided by 255).
    vals[(4 + 1) * 3 + 1] = 255.0;
    let bad = d.join("bytes.npy");
    std::fs::write(&bad, npy_raw(header, &vals)).unwrap();
    for (a, b) in [(&ok, &bad), (&bad, &ok)] {
        refused(
            &["metrics", "--reference", s(a), "--rendered", s(b)],
            &[
                "bytes.npy",
                "value 255",
                "frame 1, row 0, column 1",
                "[0, 1]",
            ],
        );
    }
    vals[5] = -0.25;
    std::fs::write(&bad, npy_raw(header, &vals)).unwrap();
    refused(
        &["metrics", "--reference", s(&ok), "--rendered", s(&bad)],
        &["bytes.npy", "value -0.25"],
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn frame_folders_are_read_in_natural_order_and_gaps_are_named() {
    let d = out_dir("frames");
    let (a, b) = (d.join("a"), d.join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    // frame_k has gray level 10 k: in text order frame_10 would come before frame_2.
    for k in 0..12u8 {
        png(&a.join(format!("frame_{k}.png")), 16, 16, 10 * k);
        png(&b.join(format!("frame_{k:04}.png")), 16, 16, 10 * k);
    }
    // Same frames, one unpadded and one padded: identical in natural order.
    let o = r4d(&[
        "metrics",
        "--reference",
        s(&a),
        "--rendered",
        s(&b),
        "--json",
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(
        j["psnr"].as_f64().is_none_or(|p| p > 60.0),
        "frames compared out of order: {out}"
    );
    // A gap: frame_5 missing.
    std::fs::remove_file(a.join("frame_5.png")).unwrap();
    refused(
        &["metrics", "--reference", s(&a), "--rendered", s(&b)],
        &[
            "frame 5",
            "frame_5.png",
            "missing",
            "frame_4.png",
            "frame_6.png",
        ],
    );
    // One number twice.
    png(&a.join("frame_5.png"), 16, 16, 50);
    png(&a.join("frame_05.png"), 16, 16, 50);
    refused(
        &["metrics", "--reference", s(&a), "--rendered", s(&b)],
        &["frame_05.png", "frame_5.png", "both are frame 5"],
    );
    std::fs::remove_file(a.join("frame_05.png")).unwrap();
    // A frame of another size.
    png(&a.join("frame_7.png"), 16, 8, 70);
    refused(
        &["metrics", "--reference", s(&a), "--rendered", s(&b)],
        &["frame_7.png", "(16, 8)"],
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn npy_headers_numpy_refuses_are_typed_errors_naming_the_file() {
    let d = out_dir("npy");
    let ok = d.join("ok.npy");
    let good = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2, 3), }";
    std::fs::write(&ok, npy_raw(good, &[0.5; 12])).unwrap();
    for (i, (header, why)) in [
        ("{'descr': '<f4', 'shape': (1, 2, 2, 3)}", "fortran_order"),
        (
            "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2, 3), 'x': 0}",
            "unexpected key 'x'",
        ),
        (
            "{'descr': '<f4', 'fortran_order': False, 'shape': [1, 2, 2, 3]}",
            "a list",
        ),
        (
            "{'descr': '<f4', 'fortran_order': False, 'shape': (1, -2, 2, 3)}",
            "negative",
        ),
        (
            "{'descr': '<f4', 'fortran_order': false, 'shape': (1, 2, 2, 3)}",
            "false",
        ),
        (
            "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2, 3)",
            "expected",
        ),
        (
            "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2, 3)}}",
            "after",
        ),
        (
            "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 2, 4)}",
            "data bytes",
        ),
    ]
    .iter()
    .enumerate()
    {
        let f = d.join(format!("case{i}.npy"));
        std::fs::write(&f, npy_raw(header, &[0.5; 12])).unwrap();
        refused(
            &["metrics", "--reference", s(&ok), "--rendered", s(&f)],
            &[&format!("case{i}.npy"), why],
        );
    }
    // A Fortran-order video reads as numpy reads it: the same video as its C-order twin.
    let mut c = Vec::new();
    for k in 0..12 {
        c.push(k as f32 / 12.0);
    }
    // Fortran order of shape (1, 2, 2, 3): index (0, i, j, ch) at i + 2 j + 4 ch.
    let mut f = vec![0f32; 12];
    for i in 0..2 {
        for j in 0..2 {
            for ch in 0..3 {
                f[i + 2 * j + 4 * ch] = c[(i * 2 + j) * 3 + ch];
            }
        }
    }
    std::fs::write(&ok, npy_raw(good, &c)).unwrap();
    let fo = d.join("fortran.npy");
    std::fs::write(
        &fo,
        npy_raw(
            "{'descr': '<f4', 'fortran_order': True, 'shape': (1, 2, 2, 3), }",
            &f,
        ),
    )
    .unwrap();
    let o = r4d(&[
        "metrics",
        "--reference",
        s(&ok),
        "--rendered",
        s(&fo),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["l1"].as_f64(), Some(0.0), "{j}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn truncated_ascii_ply_frames_are_typed_errors() {
    let d = out_dir("ply");
    let (a, b) = (d.join("ref"), d.join("sim"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    let head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let body = "0.125 0.25 0.5\n1.5 2.5 3.75\n";
    for k in 0..2 {
        std::fs::write(a.join(format!("frame_{k:04}.ply")), format!("{head}{body}")).unwrap();
        std::fs::write(b.join(format!("frame_{k:04}.ply")), format!("{head}{body}")).unwrap();
    }
    let args = [
        "metrics-trajectory",
        "--reference",
        s(&a),
        "--simulated",
        s(&b),
    ];
    let o = r4d(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Cut inside the last number (3.75 -> 3.7).
    let whole = format!("{head}{body}");
    std::fs::write(b.join("frame_0001.ply"), &whole[..whole.len() - 2]).unwrap();
    refused(&args, &["frame_0001.ply", "vertex 1", "truncated"]);
    // One row fewer than the header declares.
    std::fs::write(b.join("frame_0001.ply"), format!("{head}0.125 0.25 0.5\n")).unwrap();
    refused(&args, &["frame_0001.ply", "2 declared, 1 present"]);
    // A gap in the simulated frames' numbering.
    std::fs::write(b.join("frame_0001.ply"), &whole).unwrap();
    std::fs::write(b.join("frame_0003.ply"), &whole).unwrap();
    refused(&args, &["frame 2", "frame_0002.ply", "missing"]);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn float_options_parse_as_f64_and_name_the_flag_and_range() {
    let base = [
        "segment",
        "--scene",
        "/nonexistent/scene.ply",
        "--cameras",
        "/nonexistent/cameras.json",
        "--masks",
        "/nonexistent/masks",
        "--out",
        "/nonexistent/parts.json",
    ];
    for (flag, value, range) in [
        // 1e-300 is 0 as f32: refused, not silently a zero temperature.
        ("--temperature", "1e-300", "[0.000001, 1000000]"),
        ("--temperature", "nan", "not a finite number"),
        ("--background-weight", "1.5", "[0, 1]"),
        ("--appearance=-0.1", "-0.1", "[0, 1]"),
        ("--region-power", "1e300", "[0, 64]"),
        ("--region-static-power", "inf", "not a finite number"),
        ("--region-tau", "2e6", "[0, 1000000]"),
        ("--full-visibility", "1e40", "[0, 1000000000]"),
    ] {
        let mut args = base.to_vec();
        let name = flag.split('=').next().unwrap();
        if flag.contains('=') {
            args.push(flag);
        } else {
            args.extend([flag, value]);
        }
        refused(&args, &[name, value, range]);
    }
    let args = [
        "render",
        "--scene",
        "/nonexistent/scene.ply",
        "--camera",
        "/nonexistent/cameras.json",
        "--out",
        "/nonexistent/out",
        "--background",
        "0.5,2,0.5",
    ];
    refused(&args, &["--background", "2", "[0, 1]"]);
    // Both documented forms reach the scene (which does not exist), three values or not.
    let mut comma = args;
    comma[8] = "0.5,0.25,0.5";
    refused(&comma, &["/nonexistent/scene.ply"]);
    comma[8] = "0.5,0.25";
    refused(&comma, &["--background", "three values"]);
}
