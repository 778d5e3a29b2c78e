//! Preprocesses and validates every WGSL kernel with naga, so a broken shader fails
//! `cargo build`. Also writes, for each kernel, the preprocessed source (for wgpu) and its
//! SPIR-V (for a Vulkan/ash path), and a reflection table of the shared structs' layouts
//! (checked against the Rust `#[repr(C)]` structs by a unit test).
//!
//! Layout: `shaders/lib/*.wgsl` are included with `#import lib/NAME.wgsl` (each at most once
//! per kernel); `shaders/mpm/*.wgsl` and `shaders/splat/*.wgsl` are kernels. A kernel that
//! contains `#import atomic` is built twice: `NAME` with native `atomic<f32>` adds
//! (`lib/atomic_native.wgsl`) and `NAME_cas` with a compare-exchange loop on `atomic<u32>`
//! (`lib/atomic_cas.wgsl`).

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn preprocess(
    root: &Path,
    file: &Path,
    atomic: &str,
    seen: &mut HashSet<PathBuf>,
    out: &mut String,
) {
    let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    for line in text.lines() {
        let t = line.trim();
        if let Some(rest) = t.strip_prefix("#import ") {
            let name = rest.trim();
            let target = if name == "atomic" {
                root.join(atomic)
            } else {
                root.join(name)
            };
            if seen.insert(target.clone()) {
                writeln!(out, "// ---- {name}").unwrap();
                preprocess(root, &target, atomic, seen, out);
            }
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
}

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let root = manifest.join("shaders");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    println!("cargo:rerun-if-changed=shaders");
    let mut table = String::from(
        "/// Preprocessed WGSL kernels: (name, source).\npub const KERNELS: &[(&str, &str)] = &[\n",
    );
    let mut layouts = String::from(
        "/// A struct layout reflected by naga: (name, size, [(member, offset)]).\npub type StructLayout = (&'static str, u32, &'static [(&'static str, u32)]);\n/// Struct layouts reflected by naga.\npub const LAYOUTS: &[StructLayout] = &[\n",
    );
    let mut layout_seen = HashSet::new();
    let mut errors = Vec::new();
    for group in ["mpm", "splat"] {
        let dir = root.join(group);
        let Ok(rd) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut files: Vec<PathBuf> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
            .collect();
        files.sort();
        for f in files {
            let stem = f.file_stem().unwrap().to_str().unwrap().to_string();
            let text = std::fs::read_to_string(&f).unwrap();
            let variants: Vec<(String, &str)> = if text.contains("#import atomic") {
                vec![
                    (format!("{group}_{stem}"), "lib/atomic_native.wgsl"),
                    (format!("{group}_{stem}_cas"), "lib/atomic_cas.wgsl"),
                ]
            } else {
                vec![(format!("{group}_{stem}"), "lib/atomic_native.wgsl")]
            };
            for (name, atomic) in variants {
                let mut src = String::new();
                preprocess(&root, &f, atomic, &mut HashSet::new(), &mut src);
                let module = match naga::front::wgsl::parse_str(&src) {
                    Ok(m) => m,
                    Err(e) => {
                        errors.push(format!(
                            "{}: {}",
                            f.display(),
                            e.emit_to_string_with_path(&src, &name)
                        ));
                        continue;
                    }
                };
                let mut v = naga::valid::Validator::new(
                    naga::valid::ValidationFlags::all(),
                    naga::valid::Capabilities::all(),
                );
                let info = match v.validate(&module) {
                    Ok(i) => i,
                    Err(e) => {
                        errors.push(format!(
                            "{}: {}",
                            f.display(),
                            e.emit_to_string_with_path(&src, &name)
                        ));
                        continue;
                    }
                };
                let opts = naga::back::spv::Options {
                    bounds_check_policies: naga::proc::BoundsCheckPolicies {
                        index: naga::proc::BoundsCheckPolicy::Restrict,
                        buffer: naga::proc::BoundsCheckPolicy::Restrict,
                        image_load: naga::proc::BoundsCheckPolicy::Restrict,
                        binding_array: naga::proc::BoundsCheckPolicy::Restrict,
                    },
                    ..Default::default()
                };
                match naga::back::spv::write_vec(&module, &info, &opts, None) {
                    Ok(words) => {
                        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
                        std::fs::write(out_dir.join(format!("{name}.spv")), bytes).unwrap();
                    }
                    Err(e) => errors.push(format!("{}: SPIR-V: {e}", f.display())),
                }
                let wgsl_path = out_dir.join(format!("{name}.wgsl"));
                std::fs::write(&wgsl_path, &src).unwrap();
                writeln!(
                    table,
                    "    (\"{name}\", include_str!(concat!(env!(\"OUT_DIR\"), \"/{name}.wgsl\"))),"
                )
                .unwrap();
                for (h, ty) in module.types.iter() {
                    let _ = h;
                    if let (Some(tname), naga::TypeInner::Struct { members, span }) =
                        (&ty.name, &ty.inner)
                    {
                        if layout_seen.insert(tname.clone()) {
                            let ms: Vec<String> = members
                                .iter()
                                .map(|m| {
                                    format!(
                                        "(\"{}\", {})",
                                        m.name.clone().unwrap_or_default(),
                                        m.offset
                                    )
                                })
                                .collect();
                            writeln!(layouts, "    (\"{tname}\", {span}, &[{}]),", ms.join(", "))
                                .unwrap();
                        }
                    }
                }
            }
        }
    }
    if !errors.is_empty() {
        panic!("WGSL validation failed:\n{}", errors.join("\n"));
    }
    table.push_str("];\n");
    layouts.push_str("];\n");
    std::fs::write(out_dir.join("kernels.rs"), table + &layouts).unwrap();
}
