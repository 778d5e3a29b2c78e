//! The two LPIPS backbones as data: their convolutions (torchvision's key names and shapes),
//! the order of convolutions and max-pools, the five feature taps, and the row geometry of
//! every layer (output size, the input rows an output row range needs), from which frames
//! are split into bands of rows.

use std::ops::Range;

/// The backbone of an LPIPS metric (both with the LPIPS version 0.1 linear heads).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LpipsNet {
    /// AlexNet (torchvision's `alexnet`), taps after relu1..relu5. The lpips package's
    /// default and the paper's usual choice.
    Alex,
    /// VGG16 (torchvision's `vgg16`), taps relu1_2, relu2_2, relu3_3, relu4_3, relu5_3.
    Vgg,
}

impl LpipsNet {
    /// Both nets.
    pub const ALL: [LpipsNet; 2] = [LpipsNet::Alex, LpipsNet::Vgg];

    /// `"alex"` or `"vgg"` (the lpips package's `net=` names; JSON keys `lpips_alex`,
    /// `lpips_vgg`; the file names `alex.safetensors`, `vgg.safetensors`).
    pub fn name(self) -> &'static str {
        match self {
            LpipsNet::Alex => "alex",
            LpipsNet::Vgg => "vgg",
        }
    }

    /// The net of a name (`alex`/`alexnet`, `vgg`/`vgg16`).
    pub fn from_name(s: &str) -> Option<LpipsNet> {
        match s.to_ascii_lowercase().as_str() {
            "alex" | "alexnet" => Some(LpipsNet::Alex),
            "vgg" | "vgg16" => Some(LpipsNet::Vgg),
            _ => None,
        }
    }

    /// Every tensor of a weights file for this net, `(key, shape)`, in the order the
    /// network uses them: the convolutions' `features.N.weight` (OIHW) and
    /// `features.N.bias`, then the heads `linK.model.1.weight` (`[1, C, 1, 1]`).
    pub fn tensors(self) -> Vec<(String, Vec<usize>)> {
        let arch = Arch::of(self);
        let mut out = Vec::new();
        for c in &arch.convs {
            out.push((c.weight_key(), vec![c.cout, c.cin, c.k, c.k]));
            out.push((c.bias_key(), vec![c.cout]));
        }
        for (k, &ch) in arch.tap_channels().iter().enumerate() {
            out.push((head_key(k), vec![1, ch, 1, 1]));
        }
        out
    }

    /// The smallest frame side (rows and columns alike) the backbone accepts: smaller
    /// frames leave a feature map empty (AlexNet 31 px, VGG16 16 px).
    pub fn min_side(self) -> usize {
        let arch = Arch::of(self);
        (1..4096)
            .find(|&n| arch.levels(n).is_some())
            .expect("both nets accept frames of a few dozen pixels")
    }
}

impl std::fmt::Display for LpipsNet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The key of linear head `k` (`lin0.model.1.weight` ...), as the lpips package names it.
pub(crate) fn head_key(k: usize) -> String {
    format!("lin{k}.model.1.weight")
}

/// One convolution, followed by a ReLU in both nets.
#[derive(Clone, Debug)]
pub(crate) struct ConvSpec {
    /// torchvision's index in `features` (`features.{index}.weight`).
    pub index: usize,
    pub cout: usize,
    pub cin: usize,
    /// Square kernel side.
    pub k: usize,
    pub stride: usize,
    /// Zero padding on every side.
    pub pad: usize,
}

impl ConvSpec {
    pub fn weight_key(&self) -> String {
        format!("features.{}.weight", self.index)
    }
    pub fn bias_key(&self) -> String {
        format!("features.{}.bias", self.index)
    }
}

/// A layer: a convolution + ReLU, or a max-pool (no padding, floor mode).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Op {
    /// Convolution `i` of [`Arch::convs`], then ReLU; `Some(t)` when tap `t` is its output.
    Conv { conv: usize, tap: Option<usize> },
    /// Max-pool with a `k x k` window and stride `s`.
    Pool { k: usize, s: usize },
}

/// A backbone: convolutions and the layer order. Level 0 is the input; level `i + 1` the
/// output of layer `i`.
#[derive(Clone, Debug)]
pub(crate) struct Arch {
    pub convs: Vec<ConvSpec>,
    pub ops: Vec<Op>,
}

impl Arch {
    pub fn of(net: LpipsNet) -> Arch {
        match net {
            LpipsNet::Alex => Self::alex(),
            LpipsNet::Vgg => Self::vgg16(),
        }
    }

    fn alex() -> Arch {
        let c = |index, cout, cin, k, stride, pad| ConvSpec {
            index,
            cout,
            cin,
            k,
            stride,
            pad,
        };
        let convs = vec![
            c(0, 64, 3, 11, 4, 2),
            c(3, 192, 64, 5, 1, 2),
            c(6, 384, 192, 3, 1, 1),
            c(8, 256, 384, 3, 1, 1),
            c(10, 256, 256, 3, 1, 1),
        ];
        let pool = Op::Pool { k: 3, s: 2 };
        let conv = |i: usize| Op::Conv {
            conv: i,
            tap: Some(i),
        };
        let ops = vec![conv(0), pool, conv(1), pool, conv(2), conv(3), conv(4)];
        Arch { convs, ops }
    }

    fn vgg16() -> Arch {
        // torchvision's cfg "D": channels, 'M' = max-pool 2x2 stride 2.
        const CFG: [usize; 17] = [
            64, 64, 0, 128, 128, 0, 256, 256, 256, 0, 512, 512, 512, 0, 512, 512, 512,
        ];
        // The taps: relu1_2, relu2_2, relu3_3, relu4_3, relu5_3 (convolutions 1, 3, 6, 9, 12).
        const TAPS: [usize; 5] = [1, 3, 6, 9, 12];
        let (mut convs, mut ops) = (Vec::new(), Vec::new());
        let (mut cin, mut index) = (3, 0);
        for &v in &CFG {
            if v == 0 {
                ops.push(Op::Pool { k: 2, s: 2 });
                index += 1;
            } else {
                let i = convs.len();
                convs.push(ConvSpec {
                    index,
                    cout: v,
                    cin,
                    k: 3,
                    stride: 1,
                    pad: 1,
                });
                ops.push(Op::Conv {
                    conv: i,
                    tap: TAPS.iter().position(|&t| t == i),
                });
                cin = v;
                index += 2;
            }
        }
        Arch { convs, ops }
    }

    /// Channels of each tap, in tap order.
    pub fn tap_channels(&self) -> Vec<usize> {
        let mut ch = vec![0; 5];
        for op in &self.ops {
            if let Op::Conv { conv, tap: Some(t) } = *op {
                ch[t] = self.convs[conv].cout;
            }
        }
        ch
    }

    /// Channels at every level (level 0: 3).
    pub fn channels(&self) -> Vec<usize> {
        let mut out = vec![3];
        for op in &self.ops {
            let c = match *op {
                Op::Conv { conv, .. } => self.convs[conv].cout,
                Op::Pool { .. } => *out.last().unwrap(),
            };
            out.push(c);
        }
        out
    }

    /// The side of every level for an input side `n` (one axis), or `None` when a level
    /// would be empty.
    pub fn levels(&self, n: usize) -> Option<Vec<usize>> {
        let mut out = vec![n];
        let mut cur = n;
        for op in &self.ops {
            cur = self.out_len(op, cur)?;
            out.push(cur);
        }
        Some(out)
    }

    fn geometry(&self, op: &Op) -> (usize, usize, usize) {
        match *op {
            Op::Conv { conv, .. } => {
                let c = &self.convs[conv];
                (c.k, c.stride, c.pad)
            }
            Op::Pool { k, s } => (k, s, 0),
        }
    }

    /// Output length of a layer along one axis (PyTorch's floor rule).
    fn out_len(&self, op: &Op, n: usize) -> Option<usize> {
        let (k, s, p) = self.geometry(op);
        (n + 2 * p >= k).then(|| (n + 2 * p - k) / s + 1)
    }

    /// The input rows (clipped to `0..n_in`) that output rows `out` of layer `op` read.
    pub fn input_rows(&self, op: &Op, out: &Range<usize>, n_in: usize) -> Range<usize> {
        let (k, s, p) = self.geometry(op);
        let lo = (out.start * s).saturating_sub(p);
        let hi = ((out.end - 1) * s + k).saturating_sub(p).min(n_in);
        lo..hi
    }

    /// For each level, the tap whose output it is.
    pub fn tap_levels(&self) -> Vec<usize> {
        let mut lv = vec![0; 5];
        for (i, op) in self.ops.iter().enumerate() {
            if let Op::Conv { tap: Some(t), .. } = *op {
                lv[t] = i + 1;
            }
        }
        lv
    }

    /// Splits a frame with `rows` (level sides along the row axis, from [`Arch::levels`])
    /// into `bands` bands: band `j` owns rows `[n j / bands, n (j + 1) / bands)` of every
    /// tap of `n` rows, and computes at every level the rows its own taps and its later
    /// layers need. Every tap row is owned by exactly one band.
    pub fn plan(&self, rows: &[usize], bands: usize) -> Vec<BandPlan> {
        let taps = self.tap_levels();
        (0..bands)
            .map(|j| {
                let owned: Vec<Range<usize>> = taps
                    .iter()
                    .map(|&lv| rows[lv] * j / bands..rows[lv] * (j + 1) / bands)
                    .collect();
                let mut need: Vec<Range<usize>> = vec![0..0; rows.len()];
                for lv in (1..rows.len()).rev() {
                    let mut r = need[lv].clone();
                    if let Some(t) = taps.iter().position(|&l| l == lv) {
                        r = hull(&r, &owned[t]);
                    }
                    need[lv] = r.clone();
                    if !r.is_empty() {
                        need[lv - 1] = self.input_rows(&self.ops[lv - 1], &r, rows[lv - 1]);
                    }
                }
                BandPlan { rows: need, owned }
            })
            .collect()
    }
}

/// The smallest range holding both (an empty range holds nothing).
fn hull(a: &Range<usize>, b: &Range<usize>) -> Range<usize> {
    match (a.is_empty(), b.is_empty()) {
        (true, _) => b.clone(),
        (_, true) => a.clone(),
        _ => a.start.min(b.start)..a.end.max(b.end),
    }
}

/// What one band of a frame computes.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct BandPlan {
    /// Rows computed at every level (level 0: the input rows read).
    pub rows: Vec<Range<usize>>,
    /// Rows of every tap whose contribution this band adds.
    pub owned: Vec<Range<usize>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tensor_layouts_follow_torchvision() {
        let alex = LpipsNet::Alex.tensors();
        assert_eq!(alex.len(), 15);
        assert_eq!(alex[0], ("features.0.weight".into(), vec![64, 3, 11, 11]));
        assert_eq!(alex[9], ("features.10.bias".into(), vec![256]));
        assert_eq!(alex[14], ("lin4.model.1.weight".into(), vec![1, 256, 1, 1]));
        let vgg = LpipsNet::Vgg.tensors();
        assert_eq!(vgg.len(), 31);
        let keys: Vec<usize> = vgg
            .iter()
            .filter(|(k, _)| k.ends_with("weight") && k.starts_with("features"))
            .map(|(k, _)| k.split('.').nth(1).unwrap().parse().unwrap())
            .collect();
        assert_eq!(keys, [0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26, 28]);
        assert_eq!(
            Arch::of(LpipsNet::Vgg).tap_channels(),
            [64, 128, 256, 512, 512]
        );
    }

    #[test]
    fn level_sizes_and_minimum_sides() {
        // AlexNet at 1080 rows: conv1 269, pool 134, conv2 134, pool 66, conv3..5 66.
        let a = Arch::of(LpipsNet::Alex);
        assert_eq!(
            a.levels(1080).unwrap(),
            [1080, 269, 134, 134, 66, 66, 66, 66]
        );
        assert_eq!(LpipsNet::Alex.min_side(), 31);
        assert!(a.levels(30).is_none() && a.levels(31).is_some());
        assert_eq!(LpipsNet::Vgg.min_side(), 16);
    }

    #[test]
    fn bands_own_every_tap_row_once_and_compute_what_they_need() {
        for net in LpipsNet::ALL {
            let a = Arch::of(net);
            for h in [net.min_side(), 37, 64, 200] {
                let rows = a.levels(h).unwrap();
                for bands in [1, 2, 3, 7] {
                    let plan = a.plan(&rows, bands);
                    for (t, &lv) in a.tap_levels().iter().enumerate() {
                        let mut covered = vec![0; rows[lv]];
                        for b in &plan {
                            for r in b.owned[t].clone() {
                                covered[r] += 1;
                                assert!(b.rows[lv].contains(&r));
                            }
                        }
                        assert!(covered.iter().all(|&c| c == 1), "{net} h {h} bands {bands}");
                    }
                    for b in &plan {
                        for lv in 1..rows.len() {
                            if !b.rows[lv].is_empty() {
                                let need = a.input_rows(&a.ops[lv - 1], &b.rows[lv], rows[lv - 1]);
                                assert!(
                                    b.rows[lv - 1].start <= need.start
                                        && need.end <= b.rows[lv - 1].end
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}
