//! INRIA 3DGS PLY files: `x y z [nx ny nz] f_dc_0..2 f_rest_* opacity scale_0..2 rot_0..3`,
//! all `float` (or `double`), `f_rest` stored channel-major (all red coefficients, then green,
//! then blue). The number of `f_rest_*` properties gives the SH degree (0, 9, 24, 45 ->
//! degree 0..3).

use crate::error::{Error, Result};
use crate::gaussians::{sh_coeffs, Gaussians};
use r4d_ply::{PlyType, PlyVertices};
use std::path::Path;

/// Reads an INRIA 3DGS PLY file.
pub fn read_gaussians(path: &Path) -> Result<Gaussians> {
    let bytes =
        r4d_fsio::read_bounded(path, r4d_fsio::MAX_BINARY_BYTES).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
    parse_gaussians(&bytes, &path.display().to_string())
}

/// Parses INRIA 3DGS PLY bytes; `file` names the source in errors.
pub fn parse_gaussians(bytes: &[u8], file: &str) -> Result<Gaussians> {
    let ply = r4d_ply::parse_ply(bytes, file)?;
    from_vertices(&ply, file)
}

fn column<'a>(ply: &'a PlyVertices, name: &str, file: &str) -> Result<&'a [f32]> {
    let err = |m: String| Error::Ply {
        file: file.to_string(),
        message: m,
    };
    let col = ply
        .get(name)
        .ok_or_else(|| err(format!("missing property '{name}' (INRIA 3DGS layout)")))?;
    match ply.type_of(name) {
        Some(PlyType::F32) | Some(PlyType::F64) => {}
        Some(t) => {
            return Err(err(format!(
                "property '{name}' has type {t:?}; Gaussian parameters must be float or double"
            )))
        }
        None => unreachable!("column exists"),
    }
    if let Some(i) = col.iter().position(|v| !v.is_finite()) {
        return Err(err(format!(
            "vertex {i}: property '{name}' is {} (not finite)",
            col[i]
        )));
    }
    Ok(col)
}

fn from_vertices(ply: &PlyVertices, file: &str) -> Result<Gaussians> {
    let n = ply.count;
    let rest = ply
        .columns
        .iter()
        .filter(|(name, _)| name.starts_with("f_rest_"))
        .count();
    let sh_degree = match rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        r => {
            return Err(Error::Ply {
                file: file.to_string(),
                message: format!(
                    "{r} f_rest_* properties: expected 0, 9, 24 or 45 (SH degree 0..3)"
                ),
            })
        }
    };
    let k = sh_coeffs(sh_degree);
    let get = |name: &str| column(ply, name, file);
    let (x, y, z) = (get("x")?, get("y")?, get("z")?);
    let dc = [get("f_dc_0")?, get("f_dc_1")?, get("f_dc_2")?];
    let mut rest_cols = Vec::with_capacity(rest);
    for j in 0..rest {
        rest_cols.push(get(&format!("f_rest_{j}"))?);
    }
    let op = get("opacity")?;
    let sc = [get("scale_0")?, get("scale_1")?, get("scale_2")?];
    let rot = [get("rot_0")?, get("rot_1")?, get("rot_2")?, get("rot_3")?];
    let mut g = Gaussians {
        sh_degree,
        means: (0..n).map(|i| [x[i], y[i], z[i]]).collect(),
        log_scales: (0..n).map(|i| [sc[0][i], sc[1][i], sc[2][i]]).collect(),
        quats: (0..n)
            .map(|i| [rot[0][i], rot[1][i], rot[2][i], rot[3][i]])
            .collect(),
        opacity_logits: op.to_vec(),
        sh: vec![0.0; n * k * 3],
    };
    for i in 0..n {
        for c in 0..3 {
            g.sh[(i * k) * 3 + c] = dc[c][i];
            for kk in 1..k {
                g.sh[(i * k + kk) * 3 + c] = rest_cols[c * (k - 1) + kk - 1][i];
            }
        }
    }
    g.validate(file)?;
    Ok(g)
}

/// Writes Gaussians as an INRIA 3DGS binary PLY (normals 0).
pub fn write_gaussians(path: &Path, g: &Gaussians) -> Result<()> {
    g.validate(&path.display().to_string())?;
    let n = g.len();
    let k = g.k();
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for j in 0..3 * (k - 1) {
        names.push(format!("f_rest_{j}"));
    }
    for s in [
        "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        names.push(s.to_string());
    }
    let mut cols: Vec<Vec<f32>> = vec![Vec::with_capacity(n); names.len()];
    for i in 0..n {
        let mut row = Vec::with_capacity(names.len());
        row.extend_from_slice(&g.means[i]);
        row.extend_from_slice(&[0.0; 3]);
        for c in 0..3 {
            row.push(g.sh[(i * k) * 3 + c]);
        }
        for c in 0..3 {
            for kk in 1..k {
                row.push(g.sh[(i * k + kk) * 3 + c]);
            }
        }
        row.push(g.opacity_logits[i]);
        row.extend_from_slice(&g.log_scales[i]);
        row.extend_from_slice(&g.quats[i]);
        for (c, v) in cols.iter_mut().zip(row) {
            c.push(v);
        }
    }
    let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let col_refs: Vec<&[f32]> = cols.iter().map(Vec::as_slice).collect();
    r4d_ply::write_ply(path, &name_refs, &col_refs)?;
    Ok(())
}
