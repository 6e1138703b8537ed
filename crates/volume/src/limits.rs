//! Checks that keep a bad header from turning into an absurd allocation.

use crate::error::{Result, VolumeError};
use std::path::Path;

/// Memory this process may use for one volume, in bytes: `MemAvailable` from
/// /proc/meminfo where there is one, else 64 GiB.
pub fn available_memory() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|kb| kb.parse::<u64>().ok()).map(|kb| kb * 1024))
        })
        .unwrap_or(64 << 30)
}

/// Bytes in human units (KiB, MiB, GiB, TiB).
pub fn human_bytes(bytes: u128) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 { format!("{bytes} B") } else { format!("{v:.1} {}", units[u]) }
}

/// Validates a grid of `dims` (any rank) holding `fields` fields: every dim at
/// least 1 and the f32 samples within available memory. Returns the number of
/// samples per field.
pub fn check_dims(path: &Path, dims: &[u64], fields: u64) -> Result<usize> {
    let dims_string = dims.iter().map(|d| d.to_string()).collect::<Vec<_>>().join("x");
    if dims.contains(&0) || fields == 0 {
        return Err(VolumeError::BadDimensions {
            path: path.to_path_buf(),
            dims: dims_string,
            message: "every dimension must be at least 1".into(),
        });
    }
    let samples: u128 = dims.iter().try_fold(fields as u128, |n, &d| n.checked_mul(d as u128)).unwrap_or(u128::MAX / 4);
    let needed = samples.saturating_mul(4);
    let available = available_memory() as u128;
    if needed > available {
        return Err(VolumeError::TooLarge {
            path: path.to_path_buf(),
            dims: dims_string,
            needed: human_bytes(needed),
            available: human_bytes(available),
        });
    }
    Ok((samples / fields as u128) as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_and_absurd_dims_are_refused_with_the_memory_needed() {
        let p = Path::new("x.nrrd");
        assert!(matches!(check_dims(p, &[4, 0, 4], 1), Err(VolumeError::BadDimensions { .. })));
        let err = check_dims(p, &[100_000, 100_000, 100_000], 1).unwrap_err().to_string();
        assert!(err.contains("3.6 PiB"), "{err}");
        assert_eq!(check_dims(p, &[2, 3, 4], 2).unwrap(), 24);
    }

    #[test]
    fn human_bytes_uses_binary_units() {
        assert_eq!(human_bytes(512), "512 B");
        assert_eq!(human_bytes(3 << 20), "3.0 MiB");
    }
}
