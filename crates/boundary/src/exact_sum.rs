//! A sum of f32 values that is the same whatever order they are added in,
//! so a report counted block by block (slabs, strips of rows, tasks on other
//! machines) equals the whole volume's bit for bit.

/// Slots: one per f32 exponent field value (0 = subnormals and zeros).
const SLOTS: usize = 256;

/// The exact sum of f32 values: each value's significand is added, as an
/// integer, into the slot of its exponent, which no order of additions can
/// round; the slots are combined at the end in exponent order. A slot holds
/// at least 2^39 values (2^63 / 2^24) before it could overflow: over 500
/// billion voxels.
#[derive(Clone, serde::Serialize, serde::Deserialize)]
#[serde(into = "SlotsAndRest", from = "SlotsAndRest")]
pub(crate) struct ExactSum {
    slots: Box<[i64; SLOTS]>,
    /// The sum of the infinite and NaN values added (0 without any):
    /// adding those is commutative and associative too.
    non_finite: f32,
}

impl Default for ExactSum {
    fn default() -> ExactSum {
        ExactSum { slots: Box::new([0; SLOTS]), non_finite: 0.0 }
    }
}

impl ExactSum {
    /// Adds `x`.
    #[inline]
    pub(crate) fn add(&mut self, x: f32) {
        let bits = x.to_bits();
        let exponent = ((bits >> 23) & 0xff) as usize;
        if exponent == 0xff {
            self.non_finite += x;
            return;
        }
        // the implicit leading 1 of normal numbers; subnormals have none
        let significand = (bits & 0x7f_ffff) as i64 | if exponent > 0 { 0x80_0000 } else { 0 };
        self.slots[exponent] += if bits >> 31 == 1 { -significand } else { significand };
    }

    /// Adds every value `other` holds (as if each had been added here).
    pub(crate) fn merge(&mut self, other: &ExactSum) {
        self.slots.iter_mut().zip(other.slots.iter()).for_each(|(a, b)| *a += b);
        self.non_finite += other.non_finite;
    }

    /// The sum, rounded once per slot in a fixed order.
    pub(crate) fn value(&self) -> f64 {
        let mut sum = 0.0f64;
        for (exponent, &slot) in self.slots.iter().enumerate() {
            if slot != 0 {
                // significand * 2^(exponent - 127 - 23); subnormals share exponent 1's scale
                sum += slot as f64 * 2f64.powi(exponent.max(1) as i32 - 150);
            }
        }
        sum + self.non_finite as f64
    }
}

/// How an [`ExactSum`] is stored: its non-zero slots (most are zero) and
/// the sum of its non-finite values.
#[derive(serde::Serialize, serde::Deserialize)]
struct SlotsAndRest {
    /// (exponent, slot) for each non-zero slot.
    slots: Vec<(u8, i64)>,
    non_finite: f32,
}

impl From<ExactSum> for SlotsAndRest {
    fn from(s: ExactSum) -> SlotsAndRest {
        let slots = (0..SLOTS).filter(|&e| s.slots[e] != 0).map(|e| (e as u8, s.slots[e])).collect();
        SlotsAndRest { slots, non_finite: s.non_finite }
    }
}

impl From<SlotsAndRest> for ExactSum {
    fn from(parts: SlotsAndRest) -> ExactSum {
        let mut s = ExactSum { non_finite: parts.non_finite, ..ExactSum::default() };
        parts.slots.into_iter().for_each(|(e, v)| s.slots[e as usize] = v);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sum_of(values: &[f32]) -> f64 {
        let mut s = ExactSum::default();
        values.iter().for_each(|&v| s.add(v));
        s.value()
    }

    #[test]
    fn any_order_gives_the_same_bits_and_the_true_sum() {
        // values of very different sizes, whose f64 running sum depends on the order
        let mut values: Vec<f32> = (0..10_000)
            .map(|i| {
                let x = ((i * 7919) % 10_007) as f32 / 10_007.0;
                if i % 3 == 0 {
                    x * 1e7
                } else if i % 3 == 1 {
                    -x * 1e-6
                } else {
                    x
                }
            })
            .collect();
        values.extend([1e-40, -3e-41, 0.0, -0.0]);
        let forward = sum_of(&values);
        values.reverse();
        let backward = sum_of(&values);
        values.sort_by(f32::total_cmp);
        let sorted = sum_of(&values);
        assert_eq!(forward.to_bits(), backward.to_bits());
        assert_eq!(forward.to_bits(), sorted.to_bits());
        // the naive f64 sums of these orders differ, the exact one is within an ulp of the truth
        let naive = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
        let truth: f64 = {
            // pairs of f32 added in f64 are exact; compensated summation of the rest
            let (mut s, mut c) = (0.0f64, 0.0f64);
            for &x in &values {
                let y = x as f64 - c;
                let t = s + y;
                c = (t - s) - y;
                s = t;
            }
            s
        };
        assert!((forward - truth).abs() <= truth.abs() * 1e-15, "{forward} vs {truth}");
        assert!((naive(&values) - truth).abs() < truth.abs() * 1e-9);
    }

    #[test]
    fn small_integers_and_halves_sum_exactly() {
        let values = [3.0f32, -1.5, 0.25, 1024.0, -0.125, 7.0];
        assert_eq!(sum_of(&values), 3.0 - 1.5 + 0.25 + 1024.0 - 0.125 + 7.0);
        assert_eq!(sum_of(&[]), 0.0);
        assert_eq!(sum_of(&[f32::MIN_POSITIVE / 4.0; 4]), f32::MIN_POSITIVE as f64);
    }

    #[test]
    fn infinities_and_nan_carry_through() {
        assert_eq!(sum_of(&[1.0, f32::INFINITY, 2.0]), f64::INFINITY);
        assert!(sum_of(&[f32::INFINITY, f32::NEG_INFINITY]).is_nan());
        assert!(sum_of(&[1.0, f32::NAN]).is_nan());
    }
}
