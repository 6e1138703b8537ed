//! The binary headers of NIfTI-1 (348 bytes), NIfTI-2 (540 bytes) and
//! Analyze 7.5 (348 bytes, NIfTI-1's ancestor), read into one [`Header`] and
//! written from a grid.
//!
//! Offsets are those of nifti1.h, nifti2.h and the Mayo Analyze 7.5
//! definition. For Analyze the scaling and origin are read as SPM2 stores them
//! (and as nibabel reads a `.hdr` without a NIfTI magic): the slope in
//! `funused1`, the intercept in `funused2`, else from `glmax/glmin` and
//! `cal_max/cal_min`; the origin (1-based voxel) in `originator`.

use crate::dtype::{Endian, SampleType};
use crate::geometry::Geometry;

/// Bytes of a NIfTI-1 or Analyze header.
pub(crate) const NIFTI1_BYTES: usize = 348;
/// Bytes of a NIfTI-2 header.
pub(crate) const NIFTI2_BYTES: usize = 540;
/// The longest axis a NIfTI-1 header can state (its dims are 16-bit).
pub const NIFTI1_MAX_AXIS: usize = i16::MAX as usize;

/// Which of the three header layouts a file has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// NIfTI-1 (`n+1` single file, `ni1` pair).
    Nifti1,
    /// NIfTI-2 (`n+2` single file, `ni2` pair): 64-bit dims and doubles.
    Nifti2,
    /// Analyze 7.5: a NIfTI-1-sized header with no magic, always a pair.
    Analyze,
}

impl Kind {
    /// The format's name as `mdtf info` shows it.
    pub fn name(self, pair: bool) -> &'static str {
        match (self, pair) {
            (Kind::Nifti1, false) => "NIfTI-1",
            (Kind::Nifti1, true) => "NIfTI-1 pair (.hdr/.img)",
            (Kind::Nifti2, false) => "NIfTI-2",
            (Kind::Nifti2, true) => "NIfTI-2 pair (.hdr/.img)",
            (Kind::Analyze, _) => "Analyze 7.5 (.hdr/.img)",
        }
    }
}

/// What mdtf uses of a NIfTI-1, NIfTI-2 or Analyze header, widened to i64 and f64.
#[derive(Debug, Clone)]
pub(crate) struct Header {
    pub kind: Kind,
    /// Header and samples in two files (`.hdr` + `.img`).
    pub pair: bool,
    pub endian: Endian,
    /// dim[0] is the rank, dim[1..=rank] the sizes.
    pub dim: [i64; 8],
    pub datatype: i16,
    /// pixdim[0] is qfac, pixdim[1..=3] the spacing.
    pub pixdim: [f64; 8],
    /// Where the samples start in the data file, in bytes.
    pub vox_offset: f64,
    /// Scaling (value = slope * stored + intercept); slope 0 means none.
    pub scl_slope: f64,
    pub scl_inter: f64,
    pub xyzt_units: u8,
    pub intent_code: i32,
    pub qform_code: i32,
    pub sform_code: i32,
    /// quatern_b, quatern_c, quatern_d.
    pub quatern: [f64; 3],
    /// qoffset_x, qoffset_y, qoffset_z.
    pub qoffset: [f64; 3],
    pub srow: [[f64; 4]; 3],
    /// SPM's origin (1-based voxel indices) in an Analyze header's `originator`.
    pub analyze_origin: [i16; 3],
}

/// Reads numbers at byte offsets in one byte order.
struct Bytes<'a> {
    b: &'a [u8],
    big: bool,
}

impl Bytes<'_> {
    fn take<const N: usize>(&self, at: usize) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(&self.b[at..at + N]);
        if self.big {
            a.reverse();
        }
        a
    }
    fn i16(&self, at: usize) -> i16 {
        i16::from_le_bytes(self.take(at))
    }
    fn i32(&self, at: usize) -> i32 {
        i32::from_le_bytes(self.take(at))
    }
    fn i64(&self, at: usize) -> i64 {
        i64::from_le_bytes(self.take(at))
    }
    fn f32(&self, at: usize) -> f64 {
        f64::from(f32::from_le_bytes(self.take(at)))
    }
    fn f64(&self, at: usize) -> f64 {
        f64::from_le_bytes(self.take(at))
    }
}

/// The first 4 bytes (sizeof_hdr) as both byte orders read them.
fn sizeof_hdr(head: &[u8]) -> Option<[i32; 2]> {
    let b: [u8; 4] = head.get(..4)?.try_into().ok()?;
    Some([i32::from_le_bytes(b), i32::from_be_bytes(b)])
}

/// How many header bytes a file beginning with `head` (at least 4 bytes)
/// has, by its sizeof_hdr: 348 or 540; None for neither.
pub(crate) fn header_len(head: &[u8]) -> Option<usize> {
    let s = sizeof_hdr(head)?;
    if s.contains(&(NIFTI1_BYTES as i32)) {
        Some(NIFTI1_BYTES)
    } else if s.contains(&(NIFTI2_BYTES as i32)) {
        Some(NIFTI2_BYTES)
    } else {
        None
    }
}

/// Whether `head` (a file's first bytes) is a NIfTI-1 or NIfTI-2 header by its
/// size and magic (an Analyze header has no magic: its extension tells).
pub(crate) fn has_nifti_magic(head: &[u8]) -> bool {
    match header_len(head) {
        Some(NIFTI1_BYTES) => matches!(head.get(344..348), Some(b"n+1\0" | b"ni1\0")),
        Some(_) => matches!(head.get(4..8), Some(b"n+2\0" | b"ni2\0")),
        None => false,
    }
}

/// Parses a header of `head.len()` >= [`header_len`] bytes. `analyze_allowed`:
/// the file is a `.hdr`, where a 348-byte header without a NIfTI magic is
/// Analyze 7.5. The error says what is wrong, for the caller to put the path to.
pub(crate) fn parse(head: &[u8], analyze_allowed: bool) -> Result<Header, String> {
    let sizes = sizeof_hdr(head).ok_or("the file is shorter than 4 bytes")?;
    let Some(len) = header_len(head) else {
        return Err(format!(
            "not a NIfTI file: its first 4 bytes (sizeof_hdr) read {} (little-endian), not 348 (NIfTI-1, Analyze) or 540 (NIfTI-2)",
            sizes[0]
        ));
    };
    if head.len() < len {
        return Err(format!("only {} bytes, a header of this kind needs {len}", head.len()));
    }
    let big = sizes[0] != len as i32;
    let r = Bytes { b: head, big };
    let endian = if big { Endian::Big } else { Endian::Little };
    if len == NIFTI2_BYTES {
        let magic = &head[4..8];
        let pair = match magic {
            b"n+2\0" => false,
            b"ni2\0" => true,
            _ => return Err(format!("a 540-byte header whose magic reads '{}', not 'n+2' or 'ni2'", shown(magic))),
        };
        let mut dim = [0i64; 8];
        let mut pixdim = [0f64; 8];
        for k in 0..8 {
            dim[k] = r.i64(16 + 8 * k);
            pixdim[k] = r.f64(104 + 8 * k);
        }
        return Ok(Header {
            kind: Kind::Nifti2,
            pair,
            endian,
            dim,
            datatype: r.i16(12),
            pixdim,
            vox_offset: r.i64(168) as f64,
            scl_slope: r.f64(176),
            scl_inter: r.f64(184),
            qform_code: r.i32(344),
            sform_code: r.i32(348),
            quatern: [r.f64(352), r.f64(360), r.f64(368)],
            qoffset: [r.f64(376), r.f64(384), r.f64(392)],
            srow: [0, 1, 2].map(|row| [0, 1, 2, 3].map(|c| r.f64(400 + 32 * row + 8 * c))),
            xyzt_units: (r.i32(500) & 0xff) as u8,
            intent_code: r.i32(504),
            analyze_origin: [0; 3],
        });
    }
    let magic = &head[344..348];
    let kind_pair = match magic {
        b"n+1\0" => (Kind::Nifti1, false),
        b"ni1\0" => (Kind::Nifti1, true),
        _ if analyze_allowed => (Kind::Analyze, true),
        _ => {
            return Err(format!(
                "a 348-byte header whose magic at byte 344 reads '{}', not 'n+1' (an Analyze 7.5 header has no magic: \
                 name it .hdr, with its samples in the .img beside it)",
                shown(magic)
            ));
        }
    };
    let mut dim = [0i64; 8];
    let mut pixdim = [0f64; 8];
    for k in 0..8 {
        dim[k] = i64::from(r.i16(40 + 2 * k));
        pixdim[k] = r.f32(76 + 4 * k);
    }
    let mut h = Header {
        kind: kind_pair.0,
        pair: kind_pair.1,
        endian,
        dim,
        datatype: r.i16(70),
        pixdim,
        vox_offset: r.f32(108),
        scl_slope: r.f32(112),
        scl_inter: r.f32(116),
        xyzt_units: head[123],
        intent_code: i32::from(r.i16(68)),
        qform_code: i32::from(r.i16(252)),
        sform_code: i32::from(r.i16(254)),
        quatern: [r.f32(256), r.f32(260), r.f32(264)],
        qoffset: [r.f32(268), r.f32(272), r.f32(276)],
        srow: [0, 1, 2].map(|row| [0, 1, 2, 3].map(|c| r.f32(280 + 16 * row + 4 * c))),
        analyze_origin: [0; 3],
    };
    if h.kind == Kind::Analyze {
        // bytes 252.. hold orient and originator, not the NIfTI transforms
        (h.qform_code, h.sform_code, h.intent_code, h.xyzt_units) = (0, 0, 0, 0);
        h.analyze_origin = [0, 1, 2].map(|k| r.i16(253 + 2 * k));
        if !(h.scl_slope.is_finite() && h.scl_slope != 0.0) {
            // SPM2: from the stored and calibrated ranges, when both are set
            let (glmax, glmin) = (f64::from(r.i32(140)), f64::from(r.i32(144)));
            let (cal_max, cal_min) = (r.f32(124), r.f32(128));
            let (stored, calibrated) = (glmax - glmin, cal_max - cal_min);
            (h.scl_slope, h.scl_inter) = if stored != 0.0 && calibrated != 0.0 && calibrated.is_finite() {
                let slope = calibrated / stored;
                (slope, cal_min - slope * glmin)
            } else {
                (0.0, 0.0)
            };
        }
    }
    Ok(h)
}

fn shown(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| std::ascii::escape_default(b).to_string()).collect()
}

impl Header {
    /// The voxel-to-world (RAS) affine's top three rows. NIfTI: sform if its
    /// code is set, else qform if its code is set, else the pixdim scaling
    /// with origin 0. Analyze: x flipped (radiological), the origin at SPM's
    /// `originator` when it lies near the grid, else at the grid's centre
    /// (nibabel's and SPM's reading).
    pub fn affine(&self, dims: [usize; 3]) -> [[f64; 4]; 3] {
        let pix = [self.pixdim[1], self.pixdim[2], self.pixdim[3]];
        if self.kind == Kind::Analyze {
            let zoom = [-pix[0], pix[1], pix[2]];
            let d = dims.map(|d| d as f64);
            let o = self.analyze_origin.map(f64::from);
            let near = o.iter().any(|&v| v != 0.0) && (0..3).all(|k| o[k] > -d[k] && o[k] < 2.0 * d[k]);
            let origin: [f64; 3] = if near { o.map(|v| v - 1.0) } else { [0, 1, 2].map(|k| (d[k] - 1.0) / 2.0) };
            return [0, 1, 2].map(|row| {
                let mut r = [0.0; 4];
                r[row] = zoom[row];
                r[3] = -origin[row] * zoom[row];
                r
            });
        }
        if self.sform_code > 0 {
            self.srow
        } else if self.qform_code > 0 {
            let qfac = if self.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
            let r = super::quaternion::to_rotation(self.quatern[0], self.quatern[1], self.quatern[2]);
            let s = [pix[0].abs(), pix[1].abs(), pix[2].abs() * qfac];
            [0, 1, 2].map(|row| [r[row][0] * s[0], r[row][1] * s[1], r[row][2] * s[2], self.qoffset[row]])
        } else {
            let s = pix.map(f64::abs);
            [[s[0], 0.0, 0.0, 0.0], [0.0, s[1], 0.0, 0.0], [0.0, 0.0, s[2], 0.0]]
        }
    }
}

/// NIfTI datatype codes (nifti1.h DT_*) and bits per sample of the types mdtf writes.
pub(crate) fn datatype_code(ty: SampleType) -> Option<(i16, i16)> {
    Some(match ty {
        SampleType::U8 => (2, 8),
        SampleType::I16 => (4, 16),
        SampleType::U16 => (512, 16),
        SampleType::F32 => (16, 32),
        _ => return None,
    })
}

/// The header mdtf writes for `dims`: NIfTI-1 when every axis fits its
/// 16-bit dims, else NIfTI-2.
pub(crate) fn kind_for(dims: &[usize]) -> Kind {
    if dims.iter().all(|&d| d <= NIFTI1_MAX_AXIS) { Kind::Nifti1 } else { Kind::Nifti2 }
}

/// Puts numbers at byte offsets, little-endian.
struct Out(Vec<u8>);

impl Out {
    fn put(&mut self, at: usize, bytes: &[u8]) {
        self.0[at..at + bytes.len()].copy_from_slice(bytes);
    }
}

/// The header mdtf writes for `dims` (3 or 4 axes) on `geometry`, little-endian,
/// followed by the 4-byte empty extension flag: NIfTI-1 when every axis fits
/// its 16-bit dims, else NIfTI-2. Spacing in pixdim, sform = the exact affine,
/// qform = its rotation, both with code 1 (scanner anatomical), mm units.
/// `pair`: the magic of a `.hdr` whose samples are in a `.img` (offset 0).
/// None when `ty` is not one mdtf writes.
pub(crate) fn encode(geometry: &Geometry, dims: &[usize], ty: SampleType, pair: bool) -> Option<(Kind, Vec<u8>)> {
    let (code, bitpix) = datatype_code(ty)?;
    let kind = kind_for(dims);
    let m = geometry.world_from_voxel();
    let ([b, c, d], qfac) = super::quaternion::from_rotation(&geometry.directions);
    let mut pixdim = [qfac, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    pixdim[1..4].copy_from_slice(&geometry.spacing);
    let mut dim = [1i64; 8];
    dim[0] = dims.len() as i64;
    for (k, &n) in dims.iter().enumerate() {
        dim[k + 1] = n as i64;
    }
    let quatern = [b, c, d, m[0][3], m[1][3], m[2][3]];
    let descrip = b"mdtf";
    let mut o;
    if kind == Kind::Nifti1 {
        o = Out(vec![0u8; NIFTI1_BYTES + 4]);
        o.put(0, &(NIFTI1_BYTES as i32).to_le_bytes());
        o.0[38] = b'r'; // "regular", as nibabel writes it
        for (k, &v) in dim.iter().enumerate() {
            o.put(40 + 2 * k, &(v as i16).to_le_bytes());
        }
        o.put(70, &code.to_le_bytes());
        o.put(72, &bitpix.to_le_bytes());
        for (k, &p) in pixdim.iter().enumerate() {
            o.put(76 + 4 * k, &(p as f32).to_le_bytes());
        }
        let offset = if pair { 0.0f32 } else { (NIFTI1_BYTES + 4) as f32 };
        o.put(108, &offset.to_le_bytes());
        o.put(112, &1.0f32.to_le_bytes()); // scl_slope
        o.0[123] = 2; // NIFTI_UNITS_MM
        o.put(148, descrip);
        o.put(252, &1i16.to_le_bytes());
        o.put(254, &1i16.to_le_bytes());
        for (k, &v) in quatern.iter().enumerate() {
            o.put(256 + 4 * k, &(v as f32).to_le_bytes());
        }
        for (row, r) in m.iter().take(3).enumerate() {
            for (c, &v) in r.iter().enumerate() {
                o.put(280 + 16 * row + 4 * c, &(v as f32).to_le_bytes());
            }
        }
        o.put(344, if pair { b"ni1\0" } else { b"n+1\0" });
    } else {
        o = Out(vec![0u8; NIFTI2_BYTES + 4]);
        o.put(0, &(NIFTI2_BYTES as i32).to_le_bytes());
        o.put(4, if pair { b"ni2\0\r\n\x1a\n" } else { b"n+2\0\r\n\x1a\n" });
        o.put(12, &code.to_le_bytes());
        o.put(14, &bitpix.to_le_bytes());
        for (k, &v) in dim.iter().enumerate() {
            o.put(16 + 8 * k, &v.to_le_bytes());
        }
        for (k, &p) in pixdim.iter().enumerate() {
            o.put(104 + 8 * k, &p.to_le_bytes());
        }
        let offset: i64 = if pair { 0 } else { (NIFTI2_BYTES + 4) as i64 };
        o.put(168, &offset.to_le_bytes());
        o.put(176, &1.0f64.to_le_bytes()); // scl_slope
        o.put(240, descrip);
        o.put(344, &1i32.to_le_bytes());
        o.put(348, &1i32.to_le_bytes());
        for (k, &v) in quatern.iter().enumerate() {
            o.put(352 + 8 * k, &v.to_le_bytes());
        }
        for (row, r) in m.iter().take(3).enumerate() {
            for (c, &v) in r.iter().enumerate() {
                o.put(400 + 32 * row + 8 * c, &v.to_le_bytes());
            }
        }
        o.put(500, &2i32.to_le_bytes()); // NIFTI_UNITS_MM
    }
    Some((kind, o.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(dims: [usize; 3]) -> Geometry {
        let mut g = Geometry::new(dims, [0.5, 0.75, 2.0]);
        g.origin = [-10.0, 20.5, 3.25];
        g.directions = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        g
    }

    #[test]
    fn a_written_header_parses_back_to_its_grid_in_both_versions_and_as_a_pair() {
        for (dims, want) in [([4, 5, 6], Kind::Nifti1), ([40000, 2, 3], Kind::Nifti2)] {
            for pair in [false, true] {
                let g = grid(dims);
                let (kind, bytes) = encode(&g, &dims, SampleType::U16, pair).unwrap();
                assert_eq!(kind, want);
                let h = parse(&bytes, false).unwrap();
                assert_eq!((h.kind, h.pair, h.datatype), (want, pair, 512));
                assert_eq!(&h.dim[..4], &[3, dims[0] as i64, dims[1] as i64, dims[2] as i64]);
                assert_eq!(h.vox_offset, if pair { 0.0 } else { bytes.len() as f64 });
                let m = g.world_from_voxel();
                let a = h.affine(dims);
                for row in 0..3 {
                    for c in 0..4 {
                        assert!((a[row][c] - m[row][c]).abs() < 1e-5, "{want:?}: [{row}][{c}]");
                    }
                }
                // the qform alone gives the same grid
                let mut q = h.clone();
                q.sform_code = 0;
                let a = q.affine(dims);
                for row in 0..3 {
                    for c in 0..4 {
                        assert!((a[row][c] - m[row][c]).abs() < 1e-5, "{want:?} qform: [{row}][{c}]");
                    }
                }
            }
        }
    }

    #[test]
    fn analyze_reads_spm_scaling_and_origin_or_centres_the_grid() {
        let mut b = vec![0u8; NIFTI1_BYTES];
        b[0..4].copy_from_slice(&348i32.to_be_bytes());
        for (k, v) in [3i16, 10, 20, 30, 1].iter().enumerate() {
            b[40 + 2 * k..42 + 2 * k].copy_from_slice(&v.to_be_bytes());
        }
        b[70..72].copy_from_slice(&4i16.to_be_bytes());
        for (k, v) in [0.0f32, 2.0, 3.0, 4.0].iter().enumerate() {
            b[76 + 4 * k..80 + 4 * k].copy_from_slice(&v.to_be_bytes());
        }
        // no funused1 slope: the ranges give slope 0.5 and intercept cal_min - 0.5 * glmin
        b[124..128].copy_from_slice(&60.0f32.to_be_bytes());
        b[128..132].copy_from_slice(&10.0f32.to_be_bytes());
        b[140..144].copy_from_slice(&120i32.to_be_bytes());
        b[144..148].copy_from_slice(&20i32.to_be_bytes());
        assert!(parse(&b, false).is_err(), "no magic and not a .hdr");
        let h = parse(&b, true).unwrap();
        assert_eq!((h.kind, h.pair, h.endian), (Kind::Analyze, true, Endian::Big));
        assert_eq!((h.scl_slope, h.scl_inter), (0.5, 0.0));
        // centred: x flipped, origin at (dims - 1) / 2
        let a = h.affine([10, 20, 30]);
        assert_eq!(a, [[-2.0, 0.0, 0.0, 9.0], [0.0, 3.0, 0.0, -28.5], [0.0, 0.0, 4.0, -58.0]]);
        // SPM's origin, 1-based
        for (k, v) in [3i16, 4, 5].iter().enumerate() {
            b[253 + 2 * k..255 + 2 * k].copy_from_slice(&v.to_be_bytes());
        }
        let a = parse(&b, true).unwrap().affine([10, 20, 30]);
        assert_eq!([a[0][3], a[1][3], a[2][3]], [4.0, -9.0, -16.0]);
    }
}
