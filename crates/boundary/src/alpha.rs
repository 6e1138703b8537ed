//! Alpha (opacity) maps of distance, eqs. 9-11 of the distance paper.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// An opacity function of the distance d to the boundary (world units).
/// `a` is the opacity at the boundary (0..1), `dc` the distance where it
/// reaches 0 (0 < dc <= d_max, the paper's domain; omitted: d_max, so that
/// the map spans every distance traced), `n` > 1 the power of the nonlinear
/// maps.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum AlphaMap {
    /// Eq. 9: max(-a d / dc + a, 0).
    Linear {
        /// Opacity at d = 0.
        a: f64,
        /// Distance of zero opacity, world units (None: d_max).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        dc: Option<f64>,
    },
    /// Eq. 10: a / dc^n |d - dc|^n for d < dc, else 0 (thinner boundaries for larger n).
    Concave {
        /// Opacity at d = 0.
        a: f64,
        /// Distance of zero opacity, world units (None: d_max).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        dc: Option<f64>,
        /// Power.
        n: f64,
    },
    /// Eq. 11: max(-a d^n / dc^n + a, 0) (thicker boundaries for larger n).
    Convex {
        /// Opacity at d = 0.
        a: f64,
        /// Distance of zero opacity, world units (None: d_max).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        dc: Option<f64>,
        /// Power.
        n: f64,
    },
}

impl Default for AlphaMap {
    /// Linear in distance, a = 1, reaching 0 at d_max.
    fn default() -> AlphaMap {
        AlphaMap::Linear { a: 1.0, dc: None }
    }
}

impl AlphaMap {
    /// The opacity at distance d >= 0, with `d_max` standing for an omitted dc.
    pub fn eval(&self, d: f64, d_max: f64) -> f64 {
        let dc = |dc: Option<f64>| dc.unwrap_or(d_max);
        match *self {
            AlphaMap::Linear { a, dc: c } => {
                let dc = dc(c);
                (-a * d / dc + a).max(0.0)
            }
            AlphaMap::Concave { a, dc: c, n } => {
                let dc = dc(c);
                if d < dc { a / dc.powf(n) * (d - dc).abs().powf(n) } else { 0.0 }
            }
            AlphaMap::Convex { a, dc: c, n } => {
                let dc = dc(c);
                (-a * d.powf(n) / dc.powf(n) + a).max(0.0)
            }
        }
    }

    /// The distance of zero opacity, if given.
    pub fn dc(&self) -> Option<f64> {
        match *self {
            AlphaMap::Linear { dc, .. } | AlphaMap::Concave { dc, .. } | AlphaMap::Convex { dc, .. } => dc,
        }
    }

    /// Checks the paper's dc <= d_max (world units).
    pub fn check_within(&self, d_max: f64) -> Result<(), String> {
        match self.dc() {
            Some(dc) if dc > d_max => {
                Err(format!("alpha map {self}: dc {dc} is beyond d_max {d_max} (the paper's 0 < dc <= d_max)"))
            }
            _ => Ok(()),
        }
    }

    /// A name for files: "alpha_linear", "alpha_concave", "alpha_convex".
    pub fn file_name(&self) -> &'static str {
        match self {
            AlphaMap::Linear { .. } => "alpha_linear",
            AlphaMap::Concave { .. } => "alpha_concave",
            AlphaMap::Convex { .. } => "alpha_convex",
        }
    }

    /// Checks 0 <= a <= 1, dc > 0 (when given) and n > 1.
    pub fn validate(&self) -> Result<(), String> {
        let (a, n) = match *self {
            AlphaMap::Linear { a, .. } => (a, 2.0),
            AlphaMap::Concave { a, n, .. } | AlphaMap::Convex { a, n, .. } => (a, n),
        };
        let dc = self.dc().unwrap_or(1.0);
        if !(0.0..=1.0).contains(&a) {
            return Err(format!("alpha map {self}: a must be in [0, 1]"));
        }
        if !(dc.is_finite() && dc > 0.0) {
            return Err(format!("alpha map {self}: dc must be positive"));
        }
        if !(n.is_finite() && n > 1.0) {
            return Err(format!("alpha map {self}: n must be > 1"));
        }
        Ok(())
    }
}

impl fmt::Display for AlphaMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let dc = self.dc().map_or("d_max".to_string(), |d| d.to_string());
        match self {
            AlphaMap::Linear { a, .. } => write!(f, "linear:a={a},dc={dc}"),
            AlphaMap::Concave { a, n, .. } => write!(f, "concave:a={a},dc={dc},n={n}"),
            AlphaMap::Convex { a, n, .. } => write!(f, "convex:a={a},dc={dc},n={n}"),
        }
    }
}

impl FromStr for AlphaMap {
    type Err = String;
    /// Parses "linear:a=1,dc=3", "concave:a=0.4,dc=3,n=9", "convex:a=1,dc=3,n=3";
    /// an omitted a or n takes those values, an omitted dc (or dc=d_max) is d_max.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("bad alpha map '{s}' (e.g. linear:a=1,dc=3, concave:a=0.4,dc=3,n=9, convex:a=1,dc=3,n=3)");
        let (kind, rest) = s.split_once(':').unwrap_or((s, ""));
        let mut a = None;
        let mut dc = None;
        let mut n = None;
        for kv in rest.split(',').filter(|t| !t.is_empty()) {
            let (k, v) = kv.split_once('=').ok_or_else(bad)?;
            if k.trim() == "dc" && v.trim() == "d_max" {
                continue;
            }
            let v: f64 = v.trim().parse().map_err(|_| bad())?;
            match k.trim() {
                "a" => a = Some(v),
                "dc" => dc = Some(v),
                "n" => n = Some(v),
                _ => return Err(bad()),
            }
        }
        let map = match kind.trim() {
            "linear" => AlphaMap::Linear { a: a.unwrap_or(1.0), dc },
            "concave" => AlphaMap::Concave { a: a.unwrap_or(0.4), dc, n: n.unwrap_or(9.0) },
            "convex" => AlphaMap::Convex { a: a.unwrap_or(1.0), dc, n: n.unwrap_or(3.0) },
            _ => return Err(bad()),
        };
        map.validate()?;
        Ok(map)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_papers_examples_with_defaults() {
        assert_eq!("linear:a=1,dc=3".parse::<AlphaMap>().unwrap(), AlphaMap::Linear { a: 1.0, dc: Some(3.0) });
        assert_eq!("concave".parse::<AlphaMap>().unwrap(), AlphaMap::Concave { a: 0.4, dc: None, n: 9.0 });
        assert_eq!("convex:n=2,dc=d_max".parse::<AlphaMap>().unwrap(), AlphaMap::Convex { a: 1.0, dc: None, n: 2.0 });
        // an omitted dc is d_max: eq. 9 reaches 0 there
        let m = AlphaMap::Linear { a: 0.8, dc: None };
        assert!((m.eval(7.5, 15.0) - 0.4).abs() < 1e-12 && m.eval(15.0, 15.0) == 0.0);
        assert_eq!(m.to_string(), "linear:a=0.8,dc=d_max");
        assert!(AlphaMap::Linear { a: 1.0, dc: Some(20.0) }.check_within(15.0).is_err());
        assert!("linear:a=2".parse::<AlphaMap>().is_err());
        assert!("cubic".parse::<AlphaMap>().is_err());
        assert!("convex:n=1".parse::<AlphaMap>().is_err());
    }
}
