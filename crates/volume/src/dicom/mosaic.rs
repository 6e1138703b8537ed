//! Siemens MOSAIC images: the slices of one acquisition tiled into one
//! frame, row by row (EPI, DTI). The count and the slice normal come from
//! the Siemens CSA image header (private element (0029,1010), format "SV10");
//! the tiles form a square of ceil(sqrt(count)) tiles per side.
//!
//! Geometry (as dcm2niix and NiBabel define it): ImagePositionPatient names
//! the top-left pixel of the whole mosaic, so the first slice starts half the
//! mosaic-minus-tile size further along the row and column directions.

/// How a MOSAIC frame holds its slices.
#[derive(Debug, Clone, PartialEq)]
pub struct Mosaic {
    /// Slices in the mosaic (NumberOfImagesInMosaic).
    pub count: usize,
    /// Tiles along each side of the mosaic.
    pub tiles_per_side: usize,
    /// Columns of one tile (pixels along x).
    pub tile_cols: usize,
    /// Rows of one tile (pixels along y).
    pub tile_rows: usize,
    /// SliceNormalVector (LPS), when the CSA header gives it.
    pub normal: Option<[f64; 3]>,
}

impl Mosaic {
    /// The layout of a `cols` x `rows` mosaic of `count` slices, if it tiles.
    pub fn new(cols: usize, rows: usize, count: usize, normal: Option<[f64; 3]>) -> Option<Mosaic> {
        let side = (1..=count).find(|s| s * s >= count)?;
        (count > 0 && cols.is_multiple_of(side) && rows.is_multiple_of(side)).then(|| Mosaic {
            count,
            tiles_per_side: side,
            tile_cols: cols / side,
            tile_rows: rows / side,
            normal,
        })
    }

    /// Copies tile `slice` out of a mosaic frame of `sample` bytes per pixel.
    pub fn tile<'a>(&self, frame: &'a [u8], slice: usize, sample: usize) -> impl Iterator<Item = &'a [u8]> + 'a {
        let (tr, tc) = (slice / self.tiles_per_side, slice % self.tiles_per_side);
        let row_bytes = self.tile_cols * self.tiles_per_side * sample;
        let (first_row, x0, width) = (tr * self.tile_rows, tc * self.tile_cols * sample, self.tile_cols * sample);
        (0..self.tile_rows).map(move |r| {
            let at = (first_row + r) * row_bytes + x0;
            &frame[at..at + width]
        })
    }
}

/// The values of the CSA elements `names` in an "SV10" header, as text.
pub fn csa_values(csa: &[u8], names: &[&str]) -> Vec<Option<Vec<String>>> {
    let mut found = vec![None; names.len()];
    let word = |at: usize| csa.get(at..at + 4).map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if !csa.starts_with(b"SV10") {
        return found;
    }
    let Some(count) = word(8).filter(|&n| (0..=1024).contains(&n)) else { return found };
    let mut at = 16;
    for _ in 0..count {
        let Some(name) = csa.get(at..at + 64) else { return found };
        let name = String::from_utf8_lossy(name.split(|&b| b == 0).next().unwrap_or(&[])).into_owned();
        let Some(items) = word(at + 76).filter(|&n| (0..=1024).contains(&n)) else { return found };
        at += 84;
        let mut values = Vec::new();
        for _ in 0..items {
            let Some(len) = word(at + 4).filter(|&n| n >= 0) else { return found };
            let len = len as usize;
            at += 16;
            let Some(v) = csa.get(at..at + len) else { return found };
            let text = String::from_utf8_lossy(v.split(|&b| b == 0).next().unwrap_or(&[])).trim().to_string();
            if !text.is_empty() {
                values.push(text);
            }
            at += len.div_ceil(4) * 4;
        }
        if let Some(k) = names.iter().position(|n| *n == name) {
            found[k] = Some(values);
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_are_cut_row_by_row() {
        // a 4 x 4 mosaic of 3 slices: 2 tiles per side, each 2 x 2 pixels
        let m = Mosaic::new(4, 4, 3, None).unwrap();
        assert_eq!((m.tiles_per_side, m.tile_cols, m.tile_rows), (2, 2, 2));
        let frame: Vec<u8> = (0..16).collect();
        let tile = |k| m.tile(&frame, k, 1).flatten().copied().collect::<Vec<u8>>();
        assert_eq!(tile(0), [0, 1, 4, 5]);
        assert_eq!(tile(1), [2, 3, 6, 7]);
        assert_eq!(tile(2), [8, 9, 12, 13]);
        assert!(Mosaic::new(5, 4, 3, None).is_none());
    }

    #[test]
    fn csa_elements_are_found_by_name() {
        let mut csa = b"SV10\x04\x03\x02\x01".to_vec();
        csa.extend(2i32.to_le_bytes());
        csa.extend(77i32.to_le_bytes());
        for (name, value) in [("Other", "x"), ("NumberOfImagesInMosaic", "35      ")] {
            let mut n = name.as_bytes().to_vec();
            n.resize(64, 0);
            csa.extend(n);
            csa.extend([1i32, 0, 0, 1, 77].iter().flat_map(|v| v.to_le_bytes()));
            let mut v = value.as_bytes().to_vec();
            v.push(0);
            csa.extend([v.len() as i32, v.len() as i32, 77, v.len() as i32].iter().flat_map(|x| x.to_le_bytes()));
            let padded = v.len().div_ceil(4) * 4;
            v.resize(padded, 0);
            csa.extend(v);
        }
        let found = csa_values(&csa, &["NumberOfImagesInMosaic", "Missing"]);
        assert_eq!(found[0], Some(vec!["35".to_string()]));
        assert_eq!(found[1], None);
    }
}
