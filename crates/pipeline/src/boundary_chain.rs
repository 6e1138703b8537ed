//! value volume -> derive (g, f'', normal) -> optional bilateral pre-filter
//! of g and f'' (as the distance paper does) -> boundary tracing.

use crate::channel::Channel;
use mdtf_bilateral::{BilateralError, BilateralParams, RangeUnits};
use mdtf_boundary::{BlockTrace, BoundaryError, BoundaryInput, BoundaryOutput, BoundaryParams};
use mdtf_derive::{Border, DeriveError, DeriveParams, FieldView, FieldsView, Item, Kernel};
use mdtf_volume::{Geometry, MultiField, Volume};
use serde::{Deserialize, Serialize};

/// What holds the tracing's output volumes: a whole volume's tracing
/// ([`BoundaryOutput`]) or a block's ([`BlockTrace`]).
pub trait TracedVolumes {
    /// The volume holding traced channel `c` (one of
    /// [`crate::channel::traced`]; None for any other).
    fn traced(&self, c: Channel) -> Option<&Volume>;
    /// The same, to take it out.
    fn traced_mut(&mut self, c: Channel) -> Option<&mut Volume>;
}

/// The tracing's outputs matched to their rows of the channel table, here only.
macro_rules! traced_volumes {
    ($($t:ty),*) => {$(
        impl TracedVolumes for $t {
            fn traced(&self, c: Channel) -> Option<&Volume> {
                match c {
                    Channel::GHit => Some(&self.g_hit),
                    Channel::Hit => Some(&self.hit),
                    Channel::Distance => Some(&self.distance),
                    Channel::Dot => Some(&self.dot),
                    _ => None,
                }
            }

            fn traced_mut(&mut self, c: Channel) -> Option<&mut Volume> {
                match c {
                    Channel::GHit => Some(&mut self.g_hit),
                    Channel::Hit => Some(&mut self.hit),
                    Channel::Distance => Some(&mut self.distance),
                    Channel::Dot => Some(&mut self.dot),
                    _ => None,
                }
            }
        }
    )*};
}

traced_volumes!(BoundaryOutput, BlockTrace);

/// The traced volumes of `b` by name, in the table's order, taken out of
/// it (it keeps empty ones in their place).
pub fn take_traced(b: &mut impl TracedVolumes) -> Vec<(String, Volume)> {
    let empty = || Volume::zeros(Geometry::new([0; 3], [1.0; 3]));
    crate::channel::traced()
        .filter_map(|c| b.traced_mut(c).map(|v| (c.name(&[]), std::mem::replace(v, empty()))))
        .collect()
}

/// Parameters of the chain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct BoundaryChainParams {
    /// Derivative kernel (default: derive's default; use gauss:1 or bspline3 on noisy data).
    pub kernel: Kernel,
    /// Derive's border policy (None: derive's default, clamp).
    pub border: Option<Border>,
    /// Derive's epsilon, value units per world unit: g below it counts as 0
    /// for the normal, f'' and 1/g (None: derive's default from the value range).
    pub epsilon: Option<f32>,
    /// Optional bilateral pre-filter of g and f'' (a fraction `sigma_r` is
    /// of each channel's own finite range).
    pub prefilter: Option<BilateralParams>,
    /// Tracing parameters.
    pub boundary: BoundaryParams,
}

/// Everything the chain computed.
#[derive(Debug, Clone)]
pub struct BoundaryChainOutput {
    /// g (pre-filtered if asked).
    pub g: Volume,
    /// f'' (pre-filtered if asked).
    pub f2: Volume,
    /// Unit normal.
    pub normal: MultiField,
    /// The tracing results.
    pub boundary: BoundaryOutput,
}

/// Errors of the chain, by stage. The stage's error is in the message, not
/// a `source()` as well, so that a printed chain does not say it twice.
#[derive(Debug, thiserror::Error)]
pub enum ChainError {
    /// The derive stage failed.
    #[error("derive: {0}")]
    Derive(DeriveError),
    /// The pre-filter failed.
    #[error("pre-filter: {0}")]
    Bilateral(BilateralError),
    /// Tracing failed.
    #[error("boundary: {0}")]
    Boundary(BoundaryError),
    /// A request the chain does not know.
    #[error("{0}")]
    Unknown(String),
}

impl BoundaryChainParams {
    /// Derive's parameters for `items` with this chain's kernel, border and epsilon.
    pub fn derive(&self, items: Vec<Item>) -> DeriveParams {
        let defaults = DeriveParams::default();
        DeriveParams {
            items,
            kernel: self.kernel,
            border: self.border.unwrap_or(defaults.border),
            epsilon: self.epsilon,
            padding: None,
        }
    }
}

impl From<DeriveError> for ChainError {
    fn from(e: DeriveError) -> Self {
        ChainError::Derive(e)
    }
}

impl From<BilateralError> for ChainError {
    fn from(e: BilateralError) -> Self {
        ChainError::Bilateral(e)
    }
}

impl From<BoundaryError> for ChainError {
    fn from(e: BoundaryError) -> Self {
        ChainError::Boundary(e)
    }
}

/// Runs derive, the optional pre-filter and tracing on a value volume.
pub fn run(value: &Volume, params: &BoundaryChainParams) -> Result<BoundaryChainOutput, ChainError> {
    run_on(&value.geometry, value.samples(), params, &Placement::default())
}

/// Where the volume a chain runs on lies in a larger one, for a block
/// (z-slab) of it to give the larger volume's bits.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Placement {
    /// derive's epsilon (None: from the block's own range; a block passes
    /// the whole volume's, [`mdtf_derive::default_epsilon`]).
    pub epsilon: Option<f32>,
    /// The block's first plane in the whole volume (rays are traced in its coordinates).
    pub first_plane: usize,
}

/// [`run`] on borrowed samples (`value`: x fastest, on `geometry`), which it
/// does not copy, placed in a larger volume by `at`.
pub fn run_on(
    geometry: &Geometry,
    value: &[f32],
    params: &BoundaryChainParams,
    at: &Placement,
) -> Result<BoundaryChainOutput, ChainError> {
    let value_range = mdtf_volume::finite_range(value).map_or(0.0, |(lo, hi)| (hi - lo) as f64);
    // Check the tracing parameters before the expensive stages.
    let floor = mdtf_boundary::noise_floor(&[], value_range, geometry.min_spacing());
    mdtf_boundary::resolve(&params.boundary, geometry, value_range, floor)?;
    let d =
        DeriveParams { epsilon: at.epsilon.or(params.epsilon), ..params.derive(vec![Item::G, Item::F2, Item::Normal]) };
    let input = FieldsView::new(geometry, vec![FieldView { name: "value", samples: value }])?;
    let mut out = mdtf_derive::run_view(&input, &d, None, &|_, _| {})?;
    let take = |out: &mut mdtf_derive::DeriveOutput, item| {
        let i = out.items.iter().position(|(it, _)| *it == item).unwrap_or(0);
        out.items.remove(i).1
    };
    let normal = take(&mut out, Item::Normal);
    let f2 = first_field(take(&mut out, Item::F2));
    let g = first_field(take(&mut out, Item::G));
    let (g, f2) = prefiltered(g, f2, params)?;
    let input = BoundaryInput { g: &g, f2: &f2, normal: &normal, value_range };
    let boundary = mdtf_boundary::run_block(&input, &params.boundary, at.first_plane)?;
    Ok(BoundaryChainOutput { g, f2, normal, boundary })
}

/// The bilateral pre-filter of one channel (a fraction `sigma_r` is of the channel's own range).
pub fn prefilter(v: &Volume, p: &BilateralParams) -> Result<Volume, BilateralError> {
    let range = v.finite_range().map_or(0.0, |(lo, hi)| (hi - lo) as f64);
    mdtf_bilateral::run(v, &prefilter_params(p, range))
}

/// The pre-filter's parameters with `sigma_r` in value units, for a channel
/// whose finite range spans `range` (a block of the volume filters with the
/// whole volume's range, so it must not measure its own).
pub fn prefilter_params(p: &BilateralParams, range: f64) -> BilateralParams {
    match p.range_units {
        RangeUnits::Fraction => BilateralParams {
            sigma_r: p.sigma_r * range.max(f64::MIN_POSITIVE),
            range_units: RangeUnits::Value,
            ..p.clone()
        },
        RangeUnits::Value => p.clone(),
    }
}

/// The chain after derive: pre-filter g and f'' if asked, then trace.
pub fn trace_derived(
    g: Volume,
    f2: Volume,
    normal: MultiField,
    value_range: f64,
    params: &BoundaryChainParams,
) -> Result<BoundaryChainOutput, ChainError> {
    let (g, f2) = prefiltered(g, f2, params)?;
    let boundary =
        mdtf_boundary::run(&BoundaryInput { g: &g, f2: &f2, normal: &normal, value_range }, &params.boundary)?;
    Ok(BoundaryChainOutput { g, f2, normal, boundary })
}

/// g and f'' pre-filtered, when the chain asks for it.
fn prefiltered(g: Volume, f2: Volume, params: &BoundaryChainParams) -> Result<(Volume, Volume), BilateralError> {
    match &params.prefilter {
        Some(p) => Ok((prefilter(&g, p)?, prefilter(&f2, p)?)),
        None => Ok((g, f2)),
    }
}

fn first_field(mf: MultiField) -> Volume {
    let geometry = mf.geometry;
    let data = mf.fields.into_iter().next().map(|f| f.data).unwrap_or_default();
    Volume { geometry, data }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mdtf_datagen::erf_sphere;
    use mdtf_volume::Geometry;

    #[test]
    fn chain_traces_the_sphere_and_checks_parameters_first() {
        let ph = erf_sphere(Geometry::new([48; 3], [1.0; 3]), 15.0, 2.0, 0.0, 255.0, None);
        let v = ph.volume();
        let out = run(&v, &BoundaryChainParams::default()).unwrap();
        assert!(out.boundary.counts.hits > 1000);
        let truth = ph.truth();
        let (mut err, mut n) = (0.0, 0);
        for (i, &h) in out.boundary.hit.samples().iter().enumerate() {
            if h == 1.0 && truth.x.samples()[i].abs() < 4.0 {
                err += (out.boundary.distance.samples()[i] - truth.x.samples()[i].abs()).abs();
                n += 1;
            }
        }
        assert!(err / (n as f32) < 0.05);
        let bad = BoundaryChainParams {
            boundary: BoundaryParams { d_max: Some(1000.0), ..Default::default() },
            ..Default::default()
        };
        assert!(matches!(run(&v, &bad), Err(ChainError::Boundary(_))));
    }
}
