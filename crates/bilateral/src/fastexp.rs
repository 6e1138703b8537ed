//! exp(-t) for t >= 0 in plain f32 arithmetic that the compiler vectorises
//! (no library call in the inner loop). Relative error below 3e-7 for
//! t < 87; 0 beyond (where exp(-t) < 2e-38 anyway).

const LOG2E: f32 = std::f32::consts::LOG2_E;
// ln 2 split in a part exact in f32 and a correction (Cody-Waite).
const LN2_HI: f32 = 0.693_145_75;
const LN2_LO: f32 = 1.428_606_8e-6;
// Adding and subtracting 1.5 * 2^23 rounds an f32 to the nearest integer.
const ROUND: f32 = 12_582_912.0;

/// exp(-t), t >= 0.
#[inline(always)]
pub fn exp_neg(t: f32) -> f32 {
    let x = -(if t < 87.0 { t } else { 87.0 });
    let y = x * LOG2E + ROUND;
    let n = y - ROUND;
    // The integer n also sits in y's low mantissa bits: no float-to-int conversion needed.
    let ni = (y.to_bits() as i32).wrapping_sub(ROUND.to_bits() as i32);
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    let scale = f32::from_bits((ni.wrapping_add(127) << 23) as u32);
    let v = p * scale;
    if t < 87.0 { v } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_library_exp_to_three_parts_in_ten_million() {
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let t = i as f32 * 0.000_43;
            let want = (-(t as f64)).exp();
            let got = exp_neg(t) as f64;
            worst = worst.max(((got - want) / want).abs());
        }
        assert!(worst < 3e-7, "{worst:e}");
        assert_eq!(exp_neg(0.0), 1.0);
        assert_eq!(exp_neg(1e9), 0.0);
    }
}
