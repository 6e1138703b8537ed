//! The measures mdtf derives, their output components and what they need.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A derived measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Item {
    /// Reconstructed value (the input itself for interpolating kernels).
    Value,
    /// Gradient vector (gx, gy, gz) along the grid axes, value units per world unit.
    Grad,
    /// Gradient magnitude g = |grad f|.
    G,
    /// Unit normal grad f / g (0 where g < epsilon).
    Normal,
    /// Hessian, components xx, xy, xz, yy, yz, zz, per world unit squared.
    Hessian,
    /// Second directional derivative along the gradient, f'' = (grad f)^T H (grad f) / g^2 (0 where g < epsilon).
    F2,
    /// Laplacian, trace of the Hessian.
    Laplacian,
    /// Mean curvature of the isosurface through the sample, (k1 + k2) / 2 =
    /// (f'' - Laplacian) / (2 g), per world unit: positive where the
    /// brighter side is convex (1/r on a bright sphere of radius r), 0
    /// where g < epsilon.
    Curvature,
    /// Inverse gradient magnitude (the peak-finding paper's second axis): one
    /// field, 1 / max(g, epsilon), world units per value unit; several fields,
    /// 1 / max(sqrt(||G||), epsilon) with ||G|| the Frobenius norm of Df^T Df
    /// of the normalised fields (see [`Item::Gnorm`]), world units. For one
    /// field sqrt(||G||) = g, so the two agree.
    InvG,
    /// Surface-shading weight 1 - (1 - g / g_max)^2 in [0, 1] (Kniss et al. 9.5.4), g_max the largest g in the volume.
    Shade,
    /// Multi-field: Frobenius norm of G = Df^T Df of the fields normalised to [0, 1].
    Gnorm,
    /// Multi-field: Jacobian Df of the normalised fields, m x 3 components d{field}/d{x,y,z}.
    Jacobian,
}

/// Item names, for messages and `--help`.
pub const ITEM_NAMES: &str = "value, grad, g, normal, hessian, f2, laplacian, curvature, inv_g, shade, gnorm, jacobian";

impl Item {
    /// Every item.
    pub const ALL: [Item; 12] = [
        Item::Value,
        Item::Grad,
        Item::G,
        Item::Normal,
        Item::Hessian,
        Item::F2,
        Item::Laplacian,
        Item::Curvature,
        Item::InvG,
        Item::Shade,
        Item::Gnorm,
        Item::Jacobian,
    ];

    /// The name used on the command line and as the output file name.
    pub fn name(self) -> &'static str {
        match self {
            Item::Value => "value",
            Item::Grad => "grad",
            Item::G => "g",
            Item::Normal => "normal",
            Item::Hessian => "hessian",
            Item::F2 => "f2",
            Item::Laplacian => "laplacian",
            Item::Curvature => "curvature",
            Item::InvG => "inv_g",
            Item::Shade => "shade",
            Item::Gnorm => "gnorm",
            Item::Jacobian => "jacobian",
        }
    }

    /// Whether the item is a multi-field measure (needs several fields).
    pub fn is_multi_field(self) -> bool {
        matches!(self, Item::Gnorm | Item::Jacobian)
    }

    /// Whether the item is defined for one field and for several alike (1/g).
    pub fn is_any_field_count(self) -> bool {
        self == Item::InvG
    }

    /// Names of the output components of a single-field item.
    pub fn components(self) -> &'static [&'static str] {
        match self {
            Item::Grad => &["gx", "gy", "gz"],
            Item::Normal => &["nx", "ny", "nz"],
            Item::Hessian => &["hxx", "hxy", "hxz", "hyy", "hyz", "hzz"],
            Item::Value => &["value"],
            Item::G => &["g"],
            Item::F2 => &["f2"],
            Item::Laplacian => &["laplacian"],
            Item::Curvature => &["curvature"],
            Item::InvG => &["inv_g"],
            Item::Shade => &["shade"],
            Item::Gnorm => &["gnorm"],
            Item::Jacobian => &[],
        }
    }
}

/// Which derivative orders a set of items needs (the prerequisite closure).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Needs {
    /// The reconstructed value.
    pub value: bool,
    /// First derivatives.
    pub grad: bool,
    /// Second derivatives.
    pub hessian: bool,
}

impl Needs {
    /// The derivatives needed to compute `items`.
    pub fn of(items: &[Item]) -> Needs {
        let mut n = Needs::default();
        for item in items {
            match item {
                Item::Value => n.value = true,
                Item::Grad | Item::G | Item::Normal | Item::InvG | Item::Shade | Item::Gnorm | Item::Jacobian => {
                    n.grad = true
                }
                Item::Hessian | Item::Laplacian => n.hessian = true,
                Item::F2 | Item::Curvature => {
                    n.grad = true;
                    n.hessian = true;
                }
            }
        }
        n
    }
}

/// Error for an unknown item name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown item '{0}' (valid: {ITEM_NAMES})")]
pub struct UnknownItem(pub String);

impl FromStr for Item {
    type Err = UnknownItem;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        Item::ALL.into_iter().find(|i| i.name() == t).ok_or_else(|| UnknownItem(s.to_string()))
    }
}

impl fmt::Display for Item {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f2_needs_gradient_and_hessian_and_value_needs_neither() {
        assert_eq!(Needs::of(&[Item::F2]), Needs { value: false, grad: true, hessian: true });
        assert_eq!(Needs::of(&[Item::Value]), Needs { value: true, grad: false, hessian: false });
        assert_eq!(Needs::of(&[Item::Normal, Item::Laplacian]), Needs { value: false, grad: true, hessian: true });
    }

    #[test]
    fn names_round_trip_and_unknown_lists_valid_ones() {
        for i in Item::ALL {
            assert_eq!(i.name().parse::<Item>().unwrap(), i);
        }
        let e = "fpp".parse::<Item>().unwrap_err().to_string();
        assert!(e.contains("f2") && e.contains("gnorm"));
    }
}
