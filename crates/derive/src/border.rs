//! What a kernel sees beyond the edge of the volume.
//!
//! The anchors disagree (ITK clamps, Inviwo wraps, Teem's hvol skips the
//! border, Voreen sets the border gradient to 0, Tuvok uses one-sided
//! differences); mdtf clamps by default, like ITK's zero-flux Neumann
//! condition, and offers mirror and wrap.

use serde::{Deserialize, Serialize};

/// Border policy: how an index outside 0..n maps back into the volume.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Border {
    /// Repeat the edge sample (ITK's default). Derivatives across the edge see a flat continuation.
    #[default]
    Clamp,
    /// Reflect about the edge sample without repeating it: -1 -> 1, n -> n - 2.
    Mirror,
    /// Periodic continuation (Inviwo): -1 -> n - 1.
    Wrap,
}

/// Names for messages.
pub const BORDER_NAMES: &str = "clamp, mirror, wrap";

impl Border {
    /// Maps index `i` (possibly outside) into 0..n; n >= 1.
    #[inline]
    pub fn index(self, i: isize, n: usize) -> usize {
        let n = n as isize;
        let r = match self {
            Border::Clamp => i.clamp(0, n - 1),
            Border::Wrap => i.rem_euclid(n),
            Border::Mirror => {
                if n == 1 {
                    0
                } else {
                    let period = 2 * (n - 1);
                    let m = i.rem_euclid(period);
                    if m < n { m } else { period - m }
                }
            }
        };
        r as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn border_maps_follow_their_definitions() {
        let n = 5;
        let map = |b: Border| (-3..8).map(|i| b.index(i, n)).collect::<Vec<_>>();
        assert_eq!(map(Border::Clamp), vec![0, 0, 0, 0, 1, 2, 3, 4, 4, 4, 4]);
        assert_eq!(map(Border::Mirror), vec![3, 2, 1, 0, 1, 2, 3, 4, 3, 2, 1]);
        assert_eq!(map(Border::Wrap), vec![2, 3, 4, 0, 1, 2, 3, 4, 0, 1, 2]);
        assert_eq!(Border::Mirror.index(-4, 1), 0);
    }
}
