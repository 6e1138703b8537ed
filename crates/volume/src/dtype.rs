//! Sample types on disk and their conversion to and from the f32 used inside.

use rayon::prelude::*;
use std::fmt;

/// A sample type stored in a file. Inside mdtf every sample is f32.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SampleType {
    /// Unsigned 8-bit integer.
    U8,
    /// Signed 8-bit integer.
    I8,
    /// Unsigned 16-bit integer.
    U16,
    /// Signed 16-bit integer.
    I16,
    /// Unsigned 32-bit integer.
    U32,
    /// Signed 32-bit integer.
    I32,
    /// IEEE single precision.
    F32,
    /// IEEE double precision.
    F64,
}

/// Byte order of multi-byte samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endian {
    /// Least significant byte first (x86, ARM).
    Little,
    /// Most significant byte first.
    Big,
}

/// Names accepted for `SampleType::parse`, for error messages.
pub const SAMPLE_TYPE_NAMES: &str = "u8, i8, u16, i16, u32, i32, f32, f64";

impl SampleType {
    /// Every supported type, smallest first.
    pub const ALL: [SampleType; 8] = [
        SampleType::U8,
        SampleType::I8,
        SampleType::U16,
        SampleType::I16,
        SampleType::U32,
        SampleType::I32,
        SampleType::F32,
        SampleType::F64,
    ];

    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            SampleType::U8 | SampleType::I8 => 1,
            SampleType::U16 | SampleType::I16 => 2,
            SampleType::U32 | SampleType::I32 | SampleType::F32 => 4,
            SampleType::F64 => 8,
        }
    }

    /// Short name: u8, i16, f32 ...
    pub fn name(self) -> &'static str {
        match self {
            SampleType::U8 => "u8",
            SampleType::I8 => "i8",
            SampleType::U16 => "u16",
            SampleType::I16 => "i16",
            SampleType::U32 => "u32",
            SampleType::I32 => "i32",
            SampleType::F32 => "f32",
            SampleType::F64 => "f64",
        }
    }

    /// Parses a short name (u8 ... f64) or a common alias (uint8, float, double ...).
    pub fn parse(name: &str) -> Option<SampleType> {
        let t = match name.trim().to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "uchar" => SampleType::U8,
            "i8" | "int8" | "char" => SampleType::I8,
            "u16" | "uint16" | "ushort" => SampleType::U16,
            "i16" | "int16" | "short" => SampleType::I16,
            "u32" | "uint32" | "uint" => SampleType::U32,
            "i32" | "int32" | "int" => SampleType::I32,
            "f32" | "float32" | "float" => SampleType::F32,
            "f64" | "float64" | "double" => SampleType::F64,
            _ => return None,
        };
        Some(t)
    }

    /// True for the integer types.
    pub fn is_integer(self) -> bool {
        !matches!(self, SampleType::F32 | SampleType::F64)
    }

    /// Smallest and largest value the type holds exactly, as f64.
    pub fn range(self) -> (f64, f64) {
        match self {
            SampleType::U8 => (0.0, u8::MAX as f64),
            SampleType::I8 => (i8::MIN as f64, i8::MAX as f64),
            SampleType::U16 => (0.0, u16::MAX as f64),
            SampleType::I16 => (i16::MIN as f64, i16::MAX as f64),
            SampleType::U32 => (0.0, u32::MAX as f64),
            SampleType::I32 => (i32::MIN as f64, i32::MAX as f64),
            SampleType::F32 => (f32::MIN as f64, f32::MAX as f64),
            SampleType::F64 => (f64::MIN, f64::MAX),
        }
    }
}

impl fmt::Display for SampleType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Endian {
    /// The byte order of this machine.
    pub fn native() -> Endian {
        if cfg!(target_endian = "big") { Endian::Big } else { Endian::Little }
    }
}

macro_rules! decode_as {
    ($t:ty, $bytes:expr, $out:expr, $endian:expr) => {{
        const N: usize = std::mem::size_of::<$t>();
        for (chunk, o) in $bytes.chunks_exact(N).zip($out.iter_mut()) {
            let mut a = [0u8; N];
            a.copy_from_slice(chunk);
            *o = match $endian {
                Endian::Little => <$t>::from_le_bytes(a),
                Endian::Big => <$t>::from_be_bytes(a),
            } as f32;
        }
    }};
}

/// Decodes `out.len()` samples of type `ty` from `bytes` into f32.
/// `bytes` must hold exactly `out.len() * ty.size()` bytes (checked by the caller).
pub fn decode_samples(bytes: &[u8], ty: SampleType, endian: Endian, out: &mut [f32]) {
    debug_assert_eq!(bytes.len(), out.len() * ty.size());
    match ty {
        SampleType::U8 => decode_as!(u8, bytes, out, endian),
        SampleType::I8 => decode_as!(i8, bytes, out, endian),
        SampleType::U16 => decode_as!(u16, bytes, out, endian),
        SampleType::I16 => decode_as!(i16, bytes, out, endian),
        SampleType::U32 => decode_as!(u32, bytes, out, endian),
        SampleType::I32 => decode_as!(i32, bytes, out, endian),
        SampleType::F32 => decode_as!(f32, bytes, out, endian),
        SampleType::F64 => decode_as!(f64, bytes, out, endian),
    }
}

/// Rounds `samples` to the nearest integer (halves away from zero) and
/// clamps them to the range of an integer `ty`, as a scanner storing 8- or
/// 16-bit data would; float types are left as they are. NaN stays NaN
/// (the writer refuses it).
pub fn round_to_type(samples: &mut [f32], ty: SampleType) {
    if !ty.is_integer() {
        return;
    }
    let (lo, hi) = ty.range();
    // u32's and i32's largest values round up as f32: clamp to the largest f32 the type holds
    let below = |b: f64| if (b as f32) as f64 > b { (b as f32).next_down() } else { b as f32 };
    let (lo, hi) = (lo as f32, below(hi));
    samples.par_iter_mut().for_each(|x| *x = x.round().clamp(lo, hi));
}

/// Index and value of the first sample that `ty` cannot hold exactly, if any.
pub fn first_unrepresentable(samples: &[f32], ty: SampleType) -> Option<(usize, f32)> {
    if !ty.is_integer() {
        return None;
    }
    let (lo, hi) = ty.range();
    samples.iter().enumerate().find_map(|(i, &v)| {
        let d = v as f64;
        let ok = d.fract() == 0.0 && d >= lo && d <= hi;
        (!ok).then_some((i, v))
    })
}

macro_rules! encode_as {
    ($t:ty, $samples:expr, $endian:expr, $out:expr) => {{
        for &v in $samples {
            let x = v as $t;
            match $endian {
                Endian::Little => $out.extend_from_slice(&x.to_le_bytes()),
                Endian::Big => $out.extend_from_slice(&x.to_be_bytes()),
            }
        }
    }};
}

/// Appends the samples encoded as `ty` to `out`. Integer targets expect
/// values already checked with [`first_unrepresentable`].
pub fn encode_samples(samples: &[f32], ty: SampleType, endian: Endian, out: &mut Vec<u8>) {
    out.reserve(samples.len() * ty.size());
    match ty {
        SampleType::U8 => encode_as!(u8, samples, endian, out),
        SampleType::I8 => encode_as!(i8, samples, endian, out),
        SampleType::U16 => encode_as!(u16, samples, endian, out),
        SampleType::I16 => encode_as!(i16, samples, endian, out),
        SampleType::U32 => encode_as!(u32, samples, endian, out),
        SampleType::I32 => encode_as!(i32, samples, endian, out),
        SampleType::F32 => encode_as!(f32, samples, endian, out),
        SampleType::F64 => encode_as!(f64, samples, endian, out),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_to_a_type_rounds_halves_away_and_clamps_to_what_the_writer_takes() {
        let v = [-3.6f32, 2.5, 300.2, 65535.7, 1e12, -1e12];
        for (ty, want) in [
            (SampleType::U8, [0.0, 3.0, 255.0, 255.0, 255.0, 0.0]),
            (SampleType::U16, [0.0, 3.0, 300.0, 65535.0, 65535.0, 0.0]),
            (SampleType::I16, [-4.0, 3.0, 300.0, 32767.0, 32767.0, -32768.0]),
        ] {
            let mut x = v;
            round_to_type(&mut x, ty);
            assert_eq!(x, want, "{ty:?}");
        }
        for ty in [SampleType::U32, SampleType::I32, SampleType::I8] {
            let mut x = v;
            round_to_type(&mut x, ty);
            assert_eq!(first_unrepresentable(&x, ty), None, "{ty:?}: {x:?}");
        }
        let mut f = v;
        round_to_type(&mut f, SampleType::F32);
        assert_eq!(f, v);
    }

    #[test]
    fn encode_then_decode_is_exact_for_every_type_and_endianness() {
        for ty in SampleType::ALL {
            let (lo, hi) = ty.range();
            let lo = lo.max(-1000.0) as f32;
            let hi = hi.min(1000.0) as f32;
            let samples = vec![lo, 0.0, 1.0, hi, 7.0];
            for endian in [Endian::Little, Endian::Big] {
                let mut bytes = Vec::new();
                encode_samples(&samples, ty, endian, &mut bytes);
                assert_eq!(bytes.len(), samples.len() * ty.size());
                let mut back = vec![0.0; samples.len()];
                decode_samples(&bytes, ty, endian, &mut back);
                assert_eq!(back, samples, "{ty} {endian:?}");
            }
        }
    }

    #[test]
    fn big_endian_u16_is_read_most_significant_byte_first() {
        let mut out = [0.0f32];
        decode_samples(&[0x01, 0x02], SampleType::U16, Endian::Big, &mut out);
        assert_eq!(out[0], 258.0);
        decode_samples(&[0x01, 0x02], SampleType::U16, Endian::Little, &mut out);
        assert_eq!(out[0], 513.0);
    }

    #[test]
    fn unrepresentable_values_are_found() {
        assert_eq!(first_unrepresentable(&[1.0, 2.5], SampleType::U8), Some((1, 2.5)));
        assert_eq!(first_unrepresentable(&[1.0, 256.0], SampleType::U8), Some((1, 256.0)));
        assert_eq!(first_unrepresentable(&[-1.0], SampleType::U16), Some((0, -1.0)));
        assert_eq!(first_unrepresentable(&[0.0, 65535.0], SampleType::U16), None);
        assert_eq!(first_unrepresentable(&[0.1], SampleType::F32), None);
    }
}
