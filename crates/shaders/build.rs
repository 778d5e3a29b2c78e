//! Preprocesses and validates every WGSL kernel with naga, so a broken shader fails
//! `cargo build`, and writes the typed kernel table the crate exposes (`kernels.rs` in
//! `OUT_DIR`): per kernel its preprocessed WGSL (for wgpu), its SPIR-V (for Vulkan/ash), the
//! workgroup size and the bindings its entry point uses, all reflected by naga, so no Rust
//! code repeats a `@workgroup_size` or a binding list. Also a reflection table of the shared
//! structs' layouts (checked against the Rust `#[repr(C)]` structs by the GPU backends).
//!
//! Layout: `wgsl/lib/*.wgsl` are included with `#import lib/NAME.wgsl` (each at most once per
//! kernel); `wgsl/mpm/*.wgsl` and `wgsl/splat/*.wgsl` are kernels, one entry point `main`
//! each, every binding in group 0, numbered 0, 1, ... in the order a dispatch binds its
//! buffers. A kernel that contains `#import atomic` is built twice: with native `atomic<f32>`
//! adds (`lib/atomic_native.wgsl`) and, as its `cas` variant, with a compare-exchange loop on
//! `atomic<u32>` (`lib/atomic_cas.wgsl`).

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

/// One compiled variant of a kernel.
struct Built {
    /// Rust item name (`P2G`, `P2G_CAS`).
    item: String,
    /// Table name (`mpm_p2g`, `mpm_p2g_cas`).
    name: String,
    workgroup_size: [u32; 3],
    /// `(name, kind)` in binding order.
    bindings: Vec<(String, &'static str)>,
}

/// Compiles one variant; errors are collected, not panicked, so every broken kernel is listed.
#[allow(clippy::too_many_arguments)]
fn build(
    root: &Path,
    out_dir: &Path,
    file: &Path,
    name: &str,
    item: &str,
    atomic: &str,
    layouts: &mut String,
    layout_seen: &mut HashSet<String>,
) -> Result<Built, String> {
    let mut src = String::new();
    preprocess(root, file, atomic, &mut HashSet::new(), &mut src);
    let here = file.display();
    let module = naga::front::wgsl::parse_str(&src)
        .map_err(|e| format!("{here}: {}", e.emit_to_string_with_path(&src, name)))?;
    let mut v = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    );
    let info = v
        .validate(&module)
        .map_err(|e| format!("{here}: {}", e.emit_to_string_with_path(&src, name)))?;
    if module.entry_points.len() != 1 || module.entry_points[0].name != "main" {
        return Err(format!(
            "{here}: a kernel has exactly one entry point, `main`"
        ));
    }
    let ep = &module.entry_points[0];
    let uses = info.get_entry_point(0);
    let mut bindings: Vec<(u32, String, &'static str)> = Vec::new();
    for (h, g) in module.global_variables.iter() {
        let Some(rb) = &g.binding else { continue };
        if uses[h].is_empty() {
            continue;
        }
        if rb.group != 0 {
            return Err(format!(
                "{here}: binding {} is in group {}, not 0",
                rb.binding, rb.group
            ));
        }
        let kind = match g.space {
            naga::AddressSpace::Uniform => "Uniform",
            naga::AddressSpace::Storage { access } => {
                if access.contains(naga::StorageAccess::STORE) {
                    "Storage { read_only: false }"
                } else {
                    "Storage { read_only: true }"
                }
            }
            other => return Err(format!("{here}: unsupported address space {other:?}")),
        };
        bindings.push((rb.binding, g.name.clone().unwrap_or_default(), kind));
    }
    bindings.sort_by_key(|b| b.0);
    for (i, b) in bindings.iter().enumerate() {
        if b.0 != i as u32 {
            return Err(format!(
                "{here}: the bindings `main` uses must be numbered 0, 1, ...; found {} at position {i}",
                b.0
            ));
        }
    }
    let opts = naga::back::spv::Options {
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: naga::proc::BoundsCheckPolicy::Restrict,
            buffer: naga::proc::BoundsCheckPolicy::Restrict,
            image_load: naga::proc::BoundsCheckPolicy::Restrict,
            binding_array: naga::proc::BoundsCheckPolicy::Restrict,
        },
        ..Default::default()
    };
    let words = naga::back::spv::write_vec(&module, &info, &opts, None)
        .map_err(|e| format!("{here}: SPIR-V: {e}"))?;
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    std::fs::write(out_dir.join(format!("{name}.spv")), bytes).unwrap();
    std::fs::write(out_dir.join(format!("{name}.wgsl")), &src).unwrap();
    for (_, ty) in module.types.iter() {
        if let (Some(tname), naga::TypeInner::Struct { members, span }) = (&ty.name, &ty.inner) {
            if layout_seen.insert(tname.clone()) {
                let ms: Vec<String> = members
                    .iter()
                    .map(|m| format!("(\"{}\", {})", m.name.clone().unwrap_or_default(), m.offset))
                    .collect();
                writeln!(layouts, "    (\"{tname}\", {span}, &[{}]),", ms.join(", ")).unwrap();
            }
        }
    }
    Ok(Built {
        item: item.to_string(),
        name: name.to_string(),
        workgroup_size: ep.workgroup_size,
        bindings: bindings.into_iter().map(|b| (b.1, b.2)).collect(),
    })
}

/// The constant of one built variant.
fn emit(out: &mut String, file: &str, b: &Built, cas: Option<&str>, what: &str) {
    let name = &b.name;
    writeln!(out, "    /// `wgsl/{file}`{what}.").unwrap();
    writeln!(out, "    pub const {}: Kernel = Kernel {{", b.item).unwrap();
    writeln!(out, "        name: \"{name}\",").unwrap();
    writeln!(out, "        file: \"{file}\",").unwrap();
    writeln!(
        out,
        "        wgsl: include_str!(concat!(env!(\"OUT_DIR\"), \"/{name}.wgsl\")),"
    )
    .unwrap();
    writeln!(
        out,
        "        spirv: include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{name}.spv\")),"
    )
    .unwrap();
    writeln!(out, "        workgroup_size: {:?},", b.workgroup_size).unwrap();
    let binds: Vec<String> = b
        .bindings
        .iter()
        .map(|(n, k)| format!("Binding {{ name: \"{n}\", kind: BindingKind::{k} }}"))
        .collect();
    writeln!(out, "        bindings: &[{}],", binds.join(", ")).unwrap();
    match cas {
        Some(c) => writeln!(out, "        cas: Some(&{c}),").unwrap(),
        None => writeln!(out, "        cas: None,").unwrap(),
    }
    writeln!(out, "    }};").unwrap();
}

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let root = manifest.join("wgsl");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    println!("cargo:rerun-if-changed=wgsl");
    let mut table = String::new();
    let mut all =
        String::from("/// Every kernel (each variant once).\npub const ALL: &[&Kernel] = &[\n");
    let mut layouts = String::from(
        "/// A struct layout reflected by naga: (name, size, [(member, offset)]).\npub type StructLayout = (&'static str, u32, &'static [(&'static str, u32)]);\n/// Struct layouts reflected by naga.\npub const LAYOUTS: &[StructLayout] = &[\n",
    );
    let mut layout_seen = HashSet::new();
    let mut errors = Vec::new();
    for group in ["mpm", "splat"] {
        let dir = root.join(group);
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
            .collect();
        files.sort();
        writeln!(
            table,
            "/// The {group} kernels, one per file of `wgsl/{group}/`."
        )
        .unwrap();
        writeln!(table, "pub mod {group} {{").unwrap();
        writeln!(table, "    use crate::{{Binding, BindingKind, Kernel}};").unwrap();
        for f in files {
            let stem = f.file_stem().unwrap().to_str().unwrap().to_string();
            let rel = format!("{group}/{stem}.wgsl");
            let item = stem.to_uppercase();
            let name = format!("{group}_{stem}");
            let text = std::fs::read_to_string(&f).unwrap();
            let mut b = |name: &str, item: &str, atomic: &str| {
                build(
                    &root,
                    &out_dir,
                    &f,
                    name,
                    item,
                    atomic,
                    &mut layouts,
                    &mut layout_seen,
                )
            };
            let native = b(&name, &item, "lib/atomic_native.wgsl");
            let cas = if text.contains("#import atomic") {
                Some(b(
                    &format!("{name}_cas"),
                    &format!("{item}_CAS"),
                    "lib/atomic_cas.wgsl",
                ))
            } else {
                None
            };
            match (native, cas) {
                (Ok(n), None) => {
                    emit(&mut table, &rel, &n, None, "");
                    writeln!(all, "    &{group}::{},", n.item).unwrap();
                }
                (Ok(n), Some(Ok(c))) => {
                    let native = format!(" (native float atomics; without them use `{}`)", c.item);
                    emit(&mut table, &rel, &n, Some(&c.item), &native);
                    emit(
                        &mut table,
                        &rel,
                        &c,
                        None,
                        " (compare-exchange loop for float adds)",
                    );
                    writeln!(all, "    &{group}::{},\n    &{group}::{},", n.item, c.item).unwrap();
                }
                (n, c) => {
                    errors.extend(n.err());
                    errors.extend(c.and_then(|c| c.err()));
                }
            }
        }
        writeln!(table, "}}").unwrap();
    }
    if !errors.is_empty() {
        panic!("WGSL validation failed:\n{}", errors.join("\n"));
    }
    all.push_str("];\n");
    layouts.push_str("];\n");
    std::fs::write(out_dir.join("kernels.rs"), table + &all + &layouts).unwrap();
}
