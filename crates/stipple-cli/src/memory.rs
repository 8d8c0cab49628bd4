//! Memory estimates checked before large allocations: a command that would need more than the
//! budget stops at once with a message naming the need and the budget, instead of being
//! killed (or aborting on a failed allocation) later. The budget is the memory this process
//! can still take (free memory, and what `ulimit -v` leaves), or `--memory`.

use crate::Result;
use anyhow::anyhow;
use std::sync::OnceLock;

/// Bytes a generated point costs through rendering at most: position, normal, colour, the
/// prepared copies, splat radius and shape, and normal estimation's neighbour lists
/// (measured: 480 per point with estimation or re-orientation, 75 for the raw pipeline).
pub const BYTES_PER_POINT: u64 = 480;

/// Bytes a generated point costs in `stipple gen` (the cloud and the writer's buffer;
/// measured 75).
pub const GEN_BYTES_PER_POINT: u64 = 80;

/// Bytes a pixel costs in one frame: visibility keys per thread, depth, ids, colour
/// ping-pong buffers, the splat accumulators, the blend accumulator and the output
/// (measured: 2.0 GiB peak at 4096², about 120 per pixel).
pub const BYTES_PER_PIXEL: u64 = 128;

static FLAG: OnceLock<u64> = OnceLock::new();

/// Sets the budget from `--memory` (once, at start-up).
pub fn set_budget(bytes: u64) {
    let _ = FLAG.set(bytes);
}

/// The budget and where it comes from.
fn budget() -> Option<(u64, &'static str)> {
    if let Some(&b) = FLAG.get() {
        return Some((b, "the --memory budget"));
    }
    let b = stipple_lod::mem::available_memory()?;
    Some((
        b,
        if stipple_lod::mem::address_space_limit().is_some() {
            "the memory available (free memory, within ulimit -v)"
        } else {
            "the free memory"
        },
    ))
}

fn human(bytes: u64) -> String {
    let g = bytes as f64 / (1u64 << 30) as f64;
    if g >= 1.0 {
        format!("{g:.1} GiB")
    } else {
        format!("{:.0} MiB", bytes as f64 / (1u64 << 20) as f64)
    }
}

/// Errors when `what` (e.g. "--points 1000000000000") needs more than the budget.
pub fn check(what: &str, bytes: u64) -> Result<()> {
    match budget() {
        Some((b, source)) if bytes > b => Err(anyhow!(
            "{what} needs about {} of memory, more than {source} ({}); ask for less, or \
             raise the budget with --memory SIZE (e.g. --memory {}G) if you know it fits",
            human(bytes),
            human(b),
            bytes.div_ceil(1 << 30)
        )),
        _ => Ok(()),
    }
}

/// [`check`] for `points` points at `per_point` bytes each.
pub fn check_points(what: &str, points: u64, per_point: u64) -> Result<()> {
    check(what, points.saturating_mul(per_point))
}

/// [`check`] for a frame of `width` × `height` pixels and `layers` peeled layers.
pub fn check_frame(width: u32, height: u32, layers: u32) -> Result<()> {
    let px = width as u64 * height as u64;
    check(
        &format!("a {width}×{height} image"),
        px.saturating_mul(BYTES_PER_PIXEL + 8 * layers.saturating_sub(1) as u64),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn needs_beyond_the_budget_are_refused_with_both_figures() {
        set_budget(1 << 30);
        assert!(check("small", 1 << 20).is_ok());
        let e = check_points("--points 1000000000000", 1_000_000_000_000, 64)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--points 1000000000000") && e.contains("--memory budget (1.0 GiB)"),
            "{e}"
        );
        assert!(e.contains("--memory 59605G"), "{e}");
        assert!(check_frame(16384, 16384, 1).is_err());
        assert!(check_frame(512, 512, 6).is_ok());
    }
}
