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

/// Parses a size in bytes as people write it: a number with an optional
/// unit, binary (KiB, MiB, GiB, TiB; K, M, G, T mean the same) or decimal
/// (kB, MB, GB, TB), case-insensitive for the binary ones; e.g. "2GiB",
/// "512M", "1.5 GB", "1000000".
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (number, unit) = (t[..split].trim(), t[split..].trim());
    let value: f64 =
        number.parse().map_err(|_| format!("'{text}' is not a size: give a number and a unit, e.g. 2GiB or 512MiB"))?;
    let scale: f64 = match unit {
        "" | "B" | "b" => 1.0,
        "kB" | "KB" => 1e3,
        "MB" => 1e6,
        "GB" => 1e9,
        "TB" => 1e12,
        u => match u.to_ascii_lowercase().as_str() {
            "k" | "kib" => 1024.0,
            "m" | "mib" => 1024f64.powi(2),
            "g" | "gib" => 1024f64.powi(3),
            "t" | "tib" => 1024f64.powi(4),
            _ => return Err(format!("'{text}': unknown unit '{u}' (use B, KiB, MiB, GiB, TiB, or kB, MB, GB, TB)")),
        },
    };
    let bytes = value * scale;
    if !(bytes.is_finite() && bytes >= 1.0 && bytes < 2f64.powi(63)) {
        return Err(format!("'{text}' is not a usable size"));
    }
    Ok(bytes as u64)
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
    fn sizes_parse_in_binary_and_decimal_units() {
        assert_eq!(parse_size("2GiB"), Ok(2 << 30));
        assert_eq!(parse_size("512M"), Ok(512 << 20));
        assert_eq!(parse_size(" 1.5 GB "), Ok(1_500_000_000));
        assert_eq!(parse_size("1000000"), Ok(1_000_000));
        assert_eq!(parse_size("64kib"), Ok(64 << 10));
        assert!(parse_size("2 parsecs").unwrap_err().contains("unknown unit"));
        assert!(parse_size("GiB").unwrap_err().contains("not a size"));
        assert!(parse_size("0").is_err());
    }

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
