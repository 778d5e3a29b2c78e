//! Budgets a simulation is checked against before it allocates or starts: frames and
//! substeps (their product bounds the run time), particles sampled from shapes, and the
//! memory the grid and the particles take, against a fixed limit and against the memory the
//! machine has available. Every limit is listed in `docs/LIMITS.md`.

use crate::error::{Error, Result};

/// The most frames a simulation config may ask for (`[time] frames`, `r4d simulate --frames`).
pub const MAX_FRAMES: usize = 100_000;

/// The most substeps a simulation may run in all (frames x substeps per frame), so that a
/// `frame_dt` of 1e9 s or a `substep_dt` of 1e-300 s is refused instead of running for ever.
pub const MAX_TOTAL_SUBSTEPS: u64 = 10_000_000;

/// The most particles the `[[shapes]]` of a config may sample (estimated from the shapes'
/// lattices before sampling).
pub const MAX_SHAPE_PARTICLES: u64 = 50_000_000;

/// Bytes of one grid node (mass and momentum, four `f32`).
pub const GRID_NODE_BYTES: u64 = 16;

/// Bytes one particle takes on a backend, as an estimate for the budget: position, velocity,
/// affine and deformation matrices, volume, part, the sort keys and the saved state of a
/// frame.
pub const PARTICLE_BYTES: u64 = 256;

/// The most memory one simulation's grid and particles may take (estimated as
/// `n_grid^3 GRID_NODE_BYTES + particles PARTICLE_BYTES`): 64 GiB. The memory the machine has
/// available bounds it too ([`available_memory`]).
pub const MAX_SIMULATION_BYTES: u64 = 64 << 30;

/// The memory the machine has available now (`MemAvailable` of `/proc/meminfo`), where the
/// platform reports it.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    parse_mem_available(&text)
}

/// `MemAvailable` (bytes) of a `/proc/meminfo` text.
fn parse_mem_available(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let mut words = line.split_whitespace().skip(1);
    let value: u64 = words.next()?.parse().ok()?;
    let scale = match words.next() {
        Some("kB") => 1024,
        None => 1,
        Some(_) => return None,
    };
    value.checked_mul(scale)
}

/// The estimated memory of a simulation of `particles` particles on `n_grid`^3 nodes (bytes,
/// saturating).
pub fn simulation_bytes(n_grid: usize, particles: u64) -> u64 {
    let n = n_grid as u64;
    n.saturating_mul(n)
        .saturating_mul(n)
        .saturating_mul(GRID_NODE_BYTES)
        .saturating_add(particles.saturating_mul(PARTICLE_BYTES))
}

/// Checks an estimate of `bytes` against [`MAX_SIMULATION_BYTES`] and against `available`
/// (the machine's available memory, when known); `what` names the input that asked for it.
pub fn check_memory(what: &str, bytes: u64, available: Option<u64>) -> Result<()> {
    let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
    if bytes > MAX_SIMULATION_BYTES {
        return Err(Error::Config {
            file: what.to_string(),
            message: format!(
                "the simulation would take about {:.1} GiB, more than the limit of {:.0} GiB \
                 (MAX_SIMULATION_BYTES): lower domain.n_grid or the particle count",
                gib(bytes),
                gib(MAX_SIMULATION_BYTES)
            ),
        });
    }
    if let Some(avail) = available {
        if bytes > avail {
            return Err(Error::Config {
                file: what.to_string(),
                message: format!(
                    "the simulation would take about {:.1} GiB, more than the {:.1} GiB this \
                     machine has available: lower domain.n_grid or the particle count",
                    gib(bytes),
                    gib(avail)
                ),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_estimates_are_checked_against_the_limit_and_the_machine() {
        assert_eq!(simulation_bytes(8, 10), 512 * 16 + 10 * PARTICLE_BYTES);
        assert_eq!(simulation_bytes(usize::MAX, u64::MAX), u64::MAX);
        // n_grid 1024: 16 GiB of nodes.
        let b = simulation_bytes(1024, 0);
        assert_eq!(b, 16 << 30);
        assert!(check_memory("c.toml", b, None).is_ok());
        let e = check_memory("c.toml", b, Some(8 << 30))
            .unwrap_err()
            .to_string();
        assert!(e.contains("c.toml") && e.contains("available"), "{e}");
        let e = check_memory("c.toml", u64::MAX, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("MAX_SIMULATION_BYTES"), "{e}");
    }

    #[test]
    fn mem_available_is_read_in_kilobytes() {
        let t = "MemTotal:  100 kB\nMemAvailable:   2048 kB\n";
        assert_eq!(parse_mem_available(t), Some(2048 * 1024));
        assert_eq!(parse_mem_available("MemTotal: 1 kB\n"), None);
        assert_eq!(parse_mem_available("MemAvailable: x kB\n"), None);
    }
}
