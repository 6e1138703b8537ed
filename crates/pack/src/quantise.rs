//! Quantisation: value = offset + scale * code, for u8, u16, f16 and f32.

use serde::{Deserialize, Serialize};

/// Storage type of a texture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dtype {
    /// 8-bit unsigned codes 0..=255.
    U8,
    /// 16-bit unsigned codes 0..=65535.
    U16,
    /// IEEE half floats (stored as their 16 bits; scale 1, offset 0).
    F16,
    /// IEEE single floats (scale 1, offset 0).
    F32,
}

impl Dtype {
    /// Bytes per component.
    pub fn size(self) -> usize {
        match self {
            Dtype::U8 => 1,
            Dtype::U16 | Dtype::F16 => 2,
            Dtype::F32 => 4,
        }
    }

    /// Largest integer code, or None for float types.
    pub fn max_code(self) -> Option<f64> {
        match self {
            Dtype::U8 => Some(255.0),
            Dtype::U16 => Some(65535.0),
            _ => None,
        }
    }
}

/// How a channel's codes decode: value = offset + scale * code.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Decode {
    /// Value of code 0.
    pub offset: f64,
    /// Value step per code.
    pub scale: f64,
}

/// Errors of quantisation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum QuantiseError {
    /// max <= min or not finite: every code would decode to one value.
    #[error("channel {channel}: range [{min}, {max}] would lose all precision (max must exceed min)")]
    DegenerateRange {
        /// Channel name.
        channel: String,
        /// Lower end.
        min: f64,
        /// Upper end.
        max: f64,
    },
}

/// The decode of a range [min, max] stored as `dtype`. Integer codes span
/// the range; when `signed` and min < 0 < max, 0 is exactly code z (the
/// scale grows a little so that both ends still fit). Floats store values as
/// they are.
pub fn decode_for(channel: &str, min: f64, max: f64, dtype: Dtype, signed: bool) -> Result<Decode, QuantiseError> {
    let Some(top) = dtype.max_code() else {
        return Ok(Decode { offset: 0.0, scale: 1.0 });
    };
    if !(min.is_finite() && max.is_finite() && max > min) {
        return Err(QuantiseError::DegenerateRange { channel: channel.into(), min, max });
    }
    let scale = (max - min) / top;
    if signed && min < 0.0 && max > 0.0 {
        let z = (-min / scale).round().clamp(1.0, top - 1.0);
        let scale = (-min / z).max(max / (top - z));
        return Ok(Decode { offset: -z * scale, scale });
    }
    Ok(Decode { offset: min, scale })
}

impl Decode {
    /// The code of `v` (clamped to the type's codes), as the stored bits for floats.
    #[inline]
    pub fn code(&self, v: f32, dtype: Dtype) -> u32 {
        match dtype {
            Dtype::F32 => v.to_bits(),
            Dtype::F16 => half::f16::from_f32(v).to_bits() as u32,
            Dtype::U8 | Dtype::U16 => {
                let top = dtype.max_code().unwrap_or(255.0);
                let c = ((v as f64 - self.offset) / self.scale).round();
                if c.is_nan() { 0 } else { c.clamp(0.0, top) as u32 }
            }
        }
    }

    /// The value a stored code decodes to.
    pub fn value(&self, code: u32, dtype: Dtype) -> f64 {
        match dtype {
            Dtype::F32 => f32::from_bits(code) as f64,
            Dtype::F16 => half::f16::from_bits(code as u16).to_f64(),
            _ => self.offset + self.scale * code as f64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_of_quantise_is_within_half_a_step_and_zero_is_exact() {
        for dtype in [Dtype::U8, Dtype::U16] {
            for (min, max, signed) in [(0.0, 255.0, false), (-3.7, 11.2, true), (-40.0, 5.0, true), (10.0, 20.0, true)]
            {
                let d = decode_for("x", min, max, dtype, signed).unwrap();
                for i in 0..=1000 {
                    let v = min + (max - min) * i as f64 / 1000.0;
                    let back = d.value(d.code(v as f32, dtype), dtype);
                    assert!(
                        (back - v).abs() <= 0.5 * d.scale * (1.0 + 1e-6) + 1e-6,
                        "{dtype:?} {min} {max}: {v} -> {back}"
                    );
                }
                if signed && min < 0.0 && max > 0.0 {
                    assert_eq!(d.value(d.code(0.0, dtype), dtype), 0.0, "{dtype:?} {min} {max}");
                }
            }
        }
        let d = decode_for("x", -1.0, 1.0, Dtype::F16, true).unwrap();
        assert_eq!(d.value(d.code(0.333, Dtype::F16), Dtype::F16), half::f16::from_f32(0.333).to_f64());
        assert!(decode_for("x", 1.0, 1.0, Dtype::U8, false).is_err());
    }
}
