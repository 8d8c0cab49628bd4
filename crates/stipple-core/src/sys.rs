//! Memory figures of this process and machine (Linux `/proc`; `None` elsewhere).

fn status_kib(file: &str, key: &str) -> Option<u64> {
    let s = std::fs::read_to_string(file).ok()?;
    let line = s.lines().find(|l| l.starts_with(key))?;
    line[key.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

/// Peak resident memory of this process (VmHWM), bytes.
pub fn peak_rss() -> Option<u64> {
    status_kib("/proc/self/status", "VmHWM:").map(|k| k * 1024)
}

/// Resident memory of this process now (VmRSS), bytes.
pub fn current_rss() -> Option<u64> {
    status_kib("/proc/self/status", "VmRSS:").map(|k| k * 1024)
}

/// Physical memory of the machine, bytes.
pub fn total_memory() -> Option<u64> {
    status_kib("/proc/meminfo", "MemTotal:").map(|k| k * 1024)
}

/// Memory this process can still take, bytes: the machine's available memory (MemAvailable),
/// and under an address-space limit (`ulimit -v`) what is left of it beyond the process's
/// current size, whichever is smaller.
pub fn available_memory() -> Option<u64> {
    let free = status_kib("/proc/meminfo", "MemAvailable:").map(|k| k * 1024);
    let headroom = address_space_limit().map(|limit| {
        let used = status_kib("/proc/self/status", "VmSize:").map_or(0, |k| k * 1024);
        limit.saturating_sub(used)
    });
    match (free, headroom) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// The soft address-space limit (`ulimit -v`), bytes, when one is set.
pub fn address_space_limit() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = s.lines().find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Reserves room for `more` elements in `v`, or returns an error naming `what` and the memory
/// the system refused (instead of aborting, as `Vec::reserve` does when it is refused).
pub fn try_reserve<T>(v: &mut Vec<T>, more: usize, what: &str) -> Result<(), String> {
    v.try_reserve(more).map_err(|_| {
        format!(
            "out of memory: {what} ({more} of {} bytes) need {} MiB, which the system \
             refused; free memory, raise `ulimit -v`, or read a smaller file",
            std::mem::size_of::<T>(),
            (more as u64)
                .saturating_mul(std::mem::size_of::<T>() as u64)
                .div_ceil(1 << 20)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn try_reserve_reports_a_refusal_and_grants_a_small_request() {
        let mut v: Vec<u64> = Vec::new();
        let e = try_reserve(&mut v, usize::MAX / 16, "the test's points").unwrap_err();
        assert!(
            e.contains("the test's points") && e.contains("out of memory"),
            "{e}"
        );
        try_reserve(&mut v, 10, "ten").unwrap();
        assert!(v.capacity() >= 10);
    }
}
