//! NRRD for tables that are not volumes: histogram counts and lookup
//! tables, with `axis mins` / `axis maxs` / `labels` describing each axis.

use crate::error::Result;
use crate::output::write_file_atomically;
use std::path::Path;

/// One axis of a table: its label and the value range its samples cover
/// (cell-centred: sample i covers [min + i w, min + (i + 1) w)).
#[derive(Debug, Clone, PartialEq)]
pub struct TableAxis {
    /// Label, e.g. "v" or "g".
    pub label: String,
    /// Number of samples along the axis.
    pub size: usize,
    /// Lower edge of the first cell.
    pub min: f64,
    /// Upper edge of the last cell.
    pub max: f64,
}

fn header(axes: &[TableAxis], type_name: &str) -> String {
    let join = |f: &dyn Fn(&TableAxis) -> String| axes.iter().map(f).collect::<Vec<_>>().join(" ");
    let mut s = String::from("NRRD0005\n# written by mdtf\n");
    s += &format!("type: {type_name}\n");
    s += &format!("dimension: {}\n", axes.len());
    s += &format!("sizes: {}\n", join(&|a| a.size.to_string()));
    s += &format!("axis mins: {}\n", join(&|a| a.min.to_string()));
    s += &format!("axis maxs: {}\n", join(&|a| a.max.to_string()));
    s += &format!("centers: {}\n", join(&|_| "cell".to_string()));
    s += &format!("labels: {}\n", join(&|a| format!("\"{}\"", a.label.replace('"', "'"))));
    s += "endian: little\nencoding: raw\n\n";
    s
}

/// Writes integer counts (first axis fastest) as uint32, or as uint64
/// when a count needs more than 32 bits (a histogram of a volume of over
/// 2^32 voxels). Atomic.
pub fn write_counts_nrrd(path: &Path, axes: &[TableAxis], counts: &[u64]) -> Result<()> {
    let wide = counts.iter().any(|&c| c > u64::from(u32::MAX));
    let head = header(axes, if wide { "uint64" } else { "uint32" });
    write_file_atomically(path, |w| {
        w.write_all(head.as_bytes())?;
        for chunk in counts.chunks(1 << 16) {
            let bytes: Vec<u8> = match wide {
                true => chunk.iter().flat_map(|c| c.to_le_bytes()).collect(),
                // every count fits: checked above
                false => chunk.iter().flat_map(|&c| (c as u32).to_le_bytes()).collect(),
            };
            w.write_all(&bytes)?;
        }
        Ok(())
    })
}

/// Writes a table of already-encoded little-endian samples of the named
/// NRRD type (e.g. "uint8" RGBA with a leading 4-sample axis). Atomic.
pub fn write_table_bytes(path: &Path, axes: &[TableAxis], type_name: &str, bytes: &[u8]) -> Result<()> {
    let head = header(axes, type_name);
    write_file_atomically(path, |w| {
        w.write_all(head.as_bytes())?;
        w.write_all(bytes)
    })
}

/// Writes f32 samples (first axis fastest) as a float table. Atomic.
pub fn write_table_nrrd(path: &Path, axes: &[TableAxis], values: &[f32]) -> Result<()> {
    let head = header(axes, "float");
    write_file_atomically(path, |w| {
        w.write_all(head.as_bytes())?;
        for chunk in values.chunks(1 << 16) {
            let bytes: Vec<u8> = chunk.iter().flat_map(|v| v.to_le_bytes()).collect();
            w.write_all(&bytes)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_header_describes_every_axis() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.nrrd");
        let axes = [
            TableAxis { label: "v".into(), size: 2, min: 0.0, max: 255.0 },
            TableAxis { label: "g".into(), size: 3, min: 0.0, max: 1.5 },
        ];
        write_counts_nrrd(&p, &axes, &[1, 2, 3, 4, 5, 6]).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("type: uint32\n") && text.contains("sizes: 2 3\n"));
        assert!(text.contains("axis maxs: 255 1.5\n") && text.contains("labels: \"v\" \"g\"\n"));
        let data = &bytes[bytes.len() - 24..];
        assert_eq!(u32::from_le_bytes([data[20], data[21], data[22], data[23]]), 6);
    }

    #[test]
    fn a_count_beyond_32_bits_makes_the_file_uint64() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.nrrd");
        let axes = [TableAxis { label: "v".into(), size: 3, min: 0.0, max: 1.0 }];
        let counts = [7, u64::from(u32::MAX) + 1, 1 << 36];
        write_counts_nrrd(&p, &axes, &counts).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        assert!(String::from_utf8_lossy(&bytes).contains(
            "type: uint64
"
        ));
        let data = &bytes[bytes.len() - 24..];
        let back: Vec<u64> = data.chunks(8).map(|c| u64::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(back, counts);
    }
}
