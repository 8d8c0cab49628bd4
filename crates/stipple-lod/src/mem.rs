//! Memory figures of this process and machine (from `stipple_core::sys`), and memory sizes
//! as users write them.

pub use stipple_core::sys::{address_space_limit, available_memory, peak_rss, total_memory};

/// A size or count that is not one (the message quotes what was given).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct FigureError(pub String);

/// Parses `512M`, `6G`, `1.5GiB`, `100000000` (bytes), case-insensitive.
pub fn parse_size(s: &str) -> Result<u64, FigureError> {
    size(s).map_err(FigureError)
}

fn size(s: &str) -> Result<u64, String> {
    let t = s.trim().to_ascii_lowercase();
    let t = t.trim_end_matches("ib").trim_end_matches('b');
    let (num, mul) = match t.chars().last() {
        Some('k') => (&t[..t.len() - 1], 1u64 << 10),
        Some('m') => (&t[..t.len() - 1], 1 << 20),
        Some('g') => (&t[..t.len() - 1], 1 << 30),
        Some('t') => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a size such as 512M, 6G or 1.5GiB"))?;
    if !v.is_finite() || v <= 0.0 || v * mul as f64 > u64::MAX as f64 / 2.0 {
        return Err(format!("`{s}` is not a positive size"));
    }
    Ok((v * mul as f64) as u64)
}

/// Parses a count such as `5000000`, `5M`, `2.5m`, `32k`, `1e9`.
pub fn parse_count(s: &str) -> Result<u64, FigureError> {
    count(s).map_err(FigureError)
}

fn count(s: &str) -> Result<u64, String> {
    let t = s.trim().to_ascii_lowercase().replace('_', "");
    let (num, mul) = match t.chars().last() {
        Some('k') => (&t[..t.len() - 1], 1e3),
        Some('m') => (&t[..t.len() - 1], 1e6),
        Some('g') | Some('b') => (&t[..t.len() - 1], 1e9),
        _ => (t.as_str(), 1.0),
    };
    let v: f64 = num
        .parse()
        .map_err(|_| format!("`{s}` is not a count such as 5000000, 5M or 32k"))?;
    let v = v * mul;
    if !v.is_finite() || !(1.0..=1e15).contains(&v) || v.fract() != 0.0 {
        return Err(format!("`{s}` is not a whole positive count"));
    }
    Ok(v as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_counts_parse() {
        assert_eq!(parse_size("512M"), Ok(512 << 20));
        assert_eq!(parse_size("1.5GiB"), Ok(3 << 29));
        assert_eq!(parse_size("4096"), Ok(4096));
        assert!(parse_size("-1G").is_err());
        assert!(parse_size("lots").is_err());
        assert_eq!(parse_count("5M"), Ok(5_000_000));
        assert_eq!(parse_count("32k"), Ok(32_000));
        assert_eq!(parse_count("1e9"), Ok(1_000_000_000));
        assert!(parse_count("0").is_err());
        assert!(parse_count("2.5").is_err());
    }

    #[test]
    fn this_process_has_a_peak() {
        if cfg!(target_os = "linux") {
            assert!(peak_rss().unwrap() > 1 << 20);
            assert!(total_memory().unwrap() > 64 << 20);
        }
    }
}
