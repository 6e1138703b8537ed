//! The channel table: every per-voxel channel a run can read or compute,
//! the stage that produces it, what it needs first, and how far a block of
//! it reaches into its neighbours (its halo). Channels are typed keys; their
//! names are for files and manifests. Adding a channel is one row here plus
//! its producer in [`crate::run`].

use mdtf_derive::{Item, Kernel};
use mdtf_pack::{ChannelText, texts};

/// A per-voxel channel of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Channel {
    /// The value: the input, or its first field.
    Value,
    /// Field `k` of a multi-field input (named after the field).
    Field(usize),
    /// Gradient magnitude g = |grad f| of the value.
    G,
    /// Second directional derivative f'' of the value along its gradient.
    F2,
    /// Unit normal, x component.
    Nx,
    /// Unit normal, y component.
    Ny,
    /// Unit normal, z component.
    Nz,
    /// Inverse gradient magnitude (of ||G|| when there are several fields).
    InvG,
    /// ||Df^T Df|| of the normalised fields.
    Gnorm,
    /// g at the boundary hit.
    GHit,
    /// The tracing's hit code per voxel.
    Hit,
    /// Distance to the nearest boundary, world units.
    Distance,
    /// Dot product of the unit normals at the voxel and at its boundary hit (-1 to 1).
    Dot,
    /// The value as the kernel reconstructs it (the input itself for interpolating kernels).
    Reconstructed,
    /// Gradient component along x, value units per world unit.
    Gx,
    /// Gradient component along y, value units per world unit.
    Gy,
    /// Gradient component along z, value units per world unit.
    Gz,
    /// Hessian component xx, value units per world unit squared.
    Hxx,
    /// Hessian component xy, value units per world unit squared.
    Hxy,
    /// Hessian component xz, value units per world unit squared.
    Hxz,
    /// Hessian component yy, value units per world unit squared.
    Hyy,
    /// Hessian component yz, value units per world unit squared.
    Hyz,
    /// Hessian component zz, value units per world unit squared.
    Hzz,
    /// Laplacian, the Hessian's trace, value units per world unit squared.
    Laplacian,
    /// Mean curvature of the isosurface through the voxel, per world unit
    /// (positive where the brighter side is convex).
    Curvature,
    /// Surface-shading weight 1 - (1 - g / g_max)^2 in [0, 1], g_max the
    /// largest g of the whole volume.
    Shade,
    /// Component of the Jacobian of a several-field input's normalised
    /// fields: d field / d axis (axis 0, 1, 2: x, y, z), per world unit.
    /// Named `d{field}/d{axis}`.
    Jacobian {
        /// The field.
        field: usize,
        /// The axis.
        axis: usize,
    },
    /// g after the bilateral pre-filter (what the tracing reads when the
    /// pipeline pre-filters); a run's own, not a row: no output holds it.
    GPrefiltered,
    /// f'' after the bilateral pre-filter, likewise.
    F2Prefiltered,
}

/// The stage that makes a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Producer {
    /// Read from the input (or the phantom).
    Input,
    /// The derive pass over the value alone, with this item.
    Derive(Item),
    /// The derive pass over all the fields (several fields only), with this item.
    DeriveFields(Item),
    /// The bilateral pre-filter of g and f'' before the tracing.
    Prefilter,
    /// The boundary tracing (after the optional pre-filter of g and f'').
    Trace,
}

/// One row of the table.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    /// The channel.
    pub channel: Channel,
    /// Its name in files, manifests and pipeline files (fields use their own).
    pub name: &'static str,
    /// Who makes it for a one-field input.
    pub producer: Producer,
    /// Channels its producer reads (the derive pass over all fields reads every field).
    pub prerequisites: &'static [Channel],
    /// What it is, its units and signedness (for a packed channel, the
    /// manifest's text, from [`mdtf_pack::texts`]).
    pub text: ChannelText,
    /// Who makes it and what it is when the input has several fields (where that differs).
    pub multi: Option<(Producer, ChannelText)>,
}

const TRACE_IN: &[Channel] = &[Channel::G, Channel::F2, Channel::Nx, Channel::Ny, Channel::Nz];
const VALUE_IN: &[Channel] = &[Channel::Value];

/// A row whose producer is the same for one field and several.
const fn row(
    channel: Channel,
    name: &'static str,
    producer: Producer,
    prerequisites: &'static [Channel],
    text: ChannelText,
) -> Row {
    Row { channel, name, producer, prerequisites, text, multi: None }
}

/// A row made by the derive pass over the value with `item`.
const fn derived(channel: Channel, name: &'static str, item: Item, text: ChannelText) -> Row {
    row(channel, name, Producer::Derive(item), VALUE_IN, text)
}

/// The text of a channel the packs do not hold.
const fn text(meaning: &'static str, units: &'static str, stage: &'static str, signed: bool) -> ChannelText {
    ChannelText { meaning, units, stage, signed }
}

const PER_UNIT: &str = "value units per world unit";
const PER_UNIT2: &str = "value units per world unit^2";

/// Every named channel (the fields and the Jacobian's components are not
/// rows: their names come from the input's fields).
pub const TABLE: [Row; 25] = [
    row(Channel::Value, "v", Producer::Input, &[], texts::V),
    derived(Channel::G, "g", Item::G, texts::G),
    derived(Channel::F2, "f2", Item::F2, texts::F2),
    derived(Channel::Nx, "nx", Item::Normal, texts::NORMAL),
    derived(Channel::Ny, "ny", Item::Normal, texts::NORMAL),
    derived(Channel::Nz, "nz", Item::Normal, texts::NORMAL),
    Row {
        multi: Some((Producer::DeriveFields(Item::InvG), texts::INV_G_MULTI)),
        ..derived(Channel::InvG, "inv_g", Item::InvG, texts::INV_G)
    },
    row(Channel::Gnorm, "gnorm", Producer::DeriveFields(Item::Gnorm), &[], texts::GNORM),
    row(Channel::Distance, "distance", Producer::Trace, TRACE_IN, texts::DISTANCE),
    row(Channel::GHit, "g_hit", Producer::Trace, TRACE_IN, texts::G_HIT),
    row(
        Channel::Hit,
        "hit",
        Producer::Trace,
        TRACE_IN,
        text(
            "tracing outcome: 0 not traced (g < g_min), 1 boundary kept, 2 no zero crossing, 3 rejected",
            "code",
            "boundary",
            false,
        ),
    ),
    row(
        Channel::Dot,
        "dot",
        Producer::Trace,
        TRACE_IN,
        text("dot product of the unit normals at the voxel and at its boundary hit", "1", "boundary", true),
    ),
    derived(
        Channel::Reconstructed,
        "value",
        Item::Value,
        text("the value as the kernel reconstructs it", "input units", "derive", false),
    ),
    derived(Channel::Gx, "gx", Item::Grad, text("gradient component df/dx", PER_UNIT, "derive", true)),
    derived(Channel::Gy, "gy", Item::Grad, text("gradient component df/dy", PER_UNIT, "derive", true)),
    derived(Channel::Gz, "gz", Item::Grad, text("gradient component df/dz", PER_UNIT, "derive", true)),
    derived(Channel::Hxx, "hxx", Item::Hessian, text("Hessian component d2f/dx2", PER_UNIT2, "derive", true)),
    derived(Channel::Hxy, "hxy", Item::Hessian, text("Hessian component d2f/dxdy", PER_UNIT2, "derive", true)),
    derived(Channel::Hxz, "hxz", Item::Hessian, text("Hessian component d2f/dxdz", PER_UNIT2, "derive", true)),
    derived(Channel::Hyy, "hyy", Item::Hessian, text("Hessian component d2f/dy2", PER_UNIT2, "derive", true)),
    derived(Channel::Hyz, "hyz", Item::Hessian, text("Hessian component d2f/dydz", PER_UNIT2, "derive", true)),
    derived(Channel::Hzz, "hzz", Item::Hessian, text("Hessian component d2f/dz2", PER_UNIT2, "derive", true)),
    derived(
        Channel::Laplacian,
        "laplacian",
        Item::Laplacian,
        text("Laplacian, the Hessian's trace", PER_UNIT2, "derive", true),
    ),
    derived(
        Channel::Curvature,
        "curvature",
        Item::Curvature,
        text(
            "mean curvature (k1 + k2) / 2 of the isosurface through the voxel, positive where the brighter side \
             is convex (1/r on a bright sphere of radius r)",
            "per world unit",
            "derive",
            true,
        ),
    ),
    derived(
        Channel::Shade,
        "shade",
        Item::Shade,
        text("surface-shading weight 1 - (1 - g / g_max)^2, g_max the volume's largest g", "1", "derive", false),
    ),
];

/// The unit normal's components, x first.
pub const NORMAL: [Channel; 3] = [Channel::Nx, Channel::Ny, Channel::Nz];

/// The channels the tracing makes, in table order (distance, g_hit, hit,
/// dot): the rows whose producer is the tracing. Where each is in the
/// tracing's output: [`crate::boundary_chain::TracedVolumes`].
pub fn traced() -> impl Iterator<Item = Channel> + Clone {
    TABLE.iter().filter(|r| r.producer == Producer::Trace).map(|r| r.channel)
}

/// The names of [`traced`]'s channels, in its order.
pub fn traced_names() -> Vec<String> {
    traced().map(|c| c.name(&[])).collect()
}

/// The pre-filtered channels (not rows) and their names in a run's channel store.
const PREFILTERED: [(Channel, &str); 2] =
    [(Channel::GPrefiltered, "g_prefiltered"), (Channel::F2Prefiltered, "f2_prefiltered")];

/// The text of a Jacobian component (not a row).
const JACOBIAN: ChannelText = text(
    "component d field / d axis of the Jacobian of the fields normalised to [0, 1]",
    "per world unit",
    "derive",
    true,
);

/// Every channel name, for messages and `--help`: the table's, then the Jacobian's components.
pub fn channel_names() -> String {
    let names: Vec<&str> = TABLE.iter().map(|r| r.name).collect();
    format!("{}, or d{{field}}/d{{x,y,z}} (jacobian)", names.join(", "))
}

/// The axis names of the Jacobian's components.
const AXES: [&str; 3] = ["x", "y", "z"];

impl Channel {
    /// The channel called `name` for an input with these fields (a field's
    /// own name wins over a table name it shadows, as the input's data is what the user means).
    pub fn parse(name: &str, fields: &[String]) -> Option<Channel> {
        if let Some(k) = fields.iter().position(|f| f == name) {
            return Some(Channel::Field(k));
        }
        if let Some(row) = TABLE.iter().find(|r| r.name == name) {
            return Some(row.channel);
        }

        // d{field}/d{axis}
        let (field, axis) = name.strip_prefix('d')?.rsplit_once("/d")?;
        let field = fields.iter().position(|f| f == field)?;
        let axis = AXES.iter().position(|a| *a == axis)?;
        Some(Channel::Jacobian { field, axis })
    }

    /// The one-field run's channel whose channel store file is named
    /// `name`: a table row's, or a pre-filtered one's.
    pub fn of_store(name: &str) -> Option<Channel> {
        let prefiltered = PREFILTERED.iter().find(|(_, n)| *n == name).map(|&(c, _)| c);
        prefiltered.or_else(|| TABLE.iter().find(|r| r.name == name).map(|r| r.channel))
    }

    /// The channel called `name`, or an error listing the valid names.
    pub fn named(name: &str, fields: &[String]) -> Result<Channel, UnknownChannel> {
        Channel::parse(name, fields).ok_or_else(|| UnknownChannel {
            name: name.to_string(),
            fields: if fields.is_empty() { String::new() } else { format!(", or a field: {}", fields.join(", ")) },
        })
    }

    /// Its name in files and manifests (`fields`: the input's field names).
    pub fn name(self, fields: &[String]) -> String {
        match self {
            Channel::Field(k) => fields.get(k).cloned().unwrap_or_else(|| format!("field{k}")),
            Channel::Jacobian { field, axis } => {
                format!("d{}/d{}", Channel::Field(field).name(fields), AXES.get(axis).unwrap_or(&"?"))
            }
            Channel::GPrefiltered | Channel::F2Prefiltered => {
                PREFILTERED.iter().find(|(c, _)| *c == self).map_or("?", |(_, n)| n).to_string()
            }
            c => c.row().map_or("?", |r| r.name).to_string(),
        }
    }

    /// Its row of the table (None for the fields and the Jacobian's components).
    pub fn row(self) -> Option<&'static Row> {
        TABLE.iter().find(|r| r.channel == self)
    }

    /// Who makes it; `multi`: the input has several fields.
    pub fn producer(self, multi: bool) -> Producer {
        match self.row() {
            Some(r) if multi => r.multi.map_or(r.producer, |(p, _)| p),
            Some(r) => r.producer,
            None if matches!(self, Channel::Jacobian { .. }) => Producer::DeriveFields(Item::Jacobian),
            None if matches!(self, Channel::GPrefiltered | Channel::F2Prefiltered) => Producer::Prefilter,
            None => Producer::Input,
        }
    }

    /// What it is, its units and signedness; `multi`: the input has several fields.
    pub fn text(self, multi: bool) -> ChannelText {
        match self.row() {
            Some(r) if multi => r.multi.map_or(r.text, |(_, t)| t),
            Some(r) => r.text,
            None if matches!(self, Channel::Jacobian { .. }) => JACOBIAN,
            None if self == Channel::GPrefiltered => {
                text("g after the bilateral pre-filter", PER_UNIT, "prefilter", false)
            }
            None if self == Channel::F2Prefiltered => {
                text("f'' after the bilateral pre-filter", PER_UNIT2, "prefilter", true)
            }
            None => texts::FIELD,
        }
    }

    /// How many voxels of its neighbours along each axis (x, y, z) one voxel of
    /// the channel reads, through every stage before it: the halo a block
    /// needs to compute it exactly as the whole volume does.
    pub fn halo(self, multi: bool, reach: &Reach) -> [usize; 3] {
        match self.producer(multi) {
            Producer::Input => [0; 3],
            Producer::Derive(_) | Producer::DeriveFields(_) => reach.kernel,
            Producer::Prefilter => std::array::from_fn(|a| reach.kernel[a] + reach.prefilter[a]),
            Producer::Trace => {
                let mut h = [0; 3];
                for a in 0..3 {
                    h[a] = reach.kernel[a] + reach.prefilter[a] + reach.trace[a];
                }
                h
            }
        }
    }
}

/// A one-field run's channel travels (in a cluster task's job) as its
/// channel store name.
impl serde::Serialize for Channel {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.name(&[]))
    }
}

impl<'de> serde::Deserialize<'de> for Channel {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Channel, D::Error> {
        let name = String::deserialize(d)?;
        Channel::of_store(&name).ok_or_else(|| serde::de::Error::custom(format!("unknown channel '{name}'")))
    }
}

/// How far each stage reaches, in voxels per axis (x, y, z).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Reach {
    /// The derivative kernel's support radius.
    pub kernel: [usize; 3],
    /// The bilateral pre-filter's box radius (0 without pre-filter).
    pub prefilter: [usize; 3],
    /// The tracing: d_max, plus the two voxels past a cell's origin that g's
    /// tricubic interpolation at the hit reads.
    pub trace: [usize; 3],
}

impl Reach {
    /// The reach of `kernel`, an optional pre-filter radius and a tracing
    /// distance `d_max` (world units) on a grid of `spacing` (x, y, z).
    pub fn new(kernel: Kernel, prefilter: [usize; 3], d_max: f64, spacing: [f64; 3]) -> Reach {
        Reach {
            kernel: spacing.map(|s| kernel.axis_taps(s).radius()),
            prefilter,
            // a ray ends within d_max; g at its hit is tricubic, reading 2 voxels past the hit's cell
            trace: spacing.map(|s| (d_max / s - 1e-9).ceil().max(0.0) as usize + 2),
        }
    }
}

/// A channel name that is neither in the table nor a field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown channel '{name}' (valid: {}{fields})", channel_names())]
pub struct UnknownChannel {
    /// The name asked for.
    pub name: String,
    /// The input's fields, as text for the message.
    pub fields: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_row_is_found_by_its_name_and_names_are_the_listed_ones() {
        let listed = channel_names();
        assert!(
            listed.starts_with("v, g, f2, nx, ny, nz, inv_g, ") && listed.contains("laplacian, curvature"),
            "{listed}"
        );
        let distinct: std::collections::BTreeSet<Channel> = TABLE.iter().map(|r| r.channel).collect();
        assert_eq!(distinct.len(), TABLE.len(), "one row per channel");
        for r in &TABLE {
            assert_eq!(Channel::parse(r.name, &[]), Some(r.channel));
            assert_eq!(r.channel.name(&[]), r.name);
        }
        let fields = vec!["t1".to_string(), "g".to_string()];
        assert_eq!(Channel::parse("g", &fields), Some(Channel::Field(1)), "a field shadows a table name");
        assert_eq!(Channel::Field(1).name(&fields), "g");
        // the Jacobian's components are named after the fields
        let dg_dz = Channel::Jacobian { field: 1, axis: 2 };
        assert_eq!(Channel::parse("dg/dz", &fields), Some(dg_dz));
        assert_eq!(dg_dz.name(&fields), "dg/dz");
        assert_eq!(dg_dz.producer(true), Producer::DeriveFields(Item::Jacobian));
        assert_eq!((Channel::parse("dt2/dx", &fields), Channel::parse("dt1/dw", &fields)), (None, None));
        let e = Channel::named("nope", &fields).unwrap_err().to_string();
        assert!(e.contains("'nope'") && e.contains("distance") && e.contains("t1, g"), "{e}");
    }

    #[test]
    fn a_packed_channel_is_described_as_its_manifest_says_and_each_text_names_its_producer() {
        let fields = ["t1".to_string(), "t2".to_string()];
        for name in mdtf_pack::PROFILE_NAMES.split(", ") {
            let profile: mdtf_pack::Profile = name.parse().unwrap();
            for fs in [&[][..], &fields[..]] {
                let multi = !fs.is_empty();
                for c in profile.channels(fs) {
                    let channel = Channel::parse(&c, fs).unwrap();
                    assert_eq!(channel.text(multi), mdtf_pack::describe(&c, multi), "{name}: {c}");
                }
            }
        }
        // every row's text names the stage of its producer; signed where the channel takes both signs
        for r in &TABLE {
            for multi in [false, true] {
                let stage = match r.channel.producer(multi) {
                    Producer::Input => "input",
                    Producer::Derive(_) | Producer::DeriveFields(_) => "derive",
                    Producer::Prefilter => "prefilter",
                    Producer::Trace => "boundary",
                };
                assert_eq!(r.channel.text(multi).stage, stage, "{}", r.name);
            }
        }
        let signed: Vec<&str> = TABLE.iter().filter(|r| r.text.signed).map(|r| r.name).collect();
        assert_eq!(
            signed,
            [
                "f2",
                "nx",
                "ny",
                "nz",
                "dot",
                "gx",
                "gy",
                "gz",
                "hxx",
                "hxy",
                "hxz",
                "hyy",
                "hyz",
                "hzz",
                "laplacian",
                "curvature"
            ]
        );
        assert_eq!(Channel::InvG.text(true).units, "world units");
        assert_eq!(Channel::InvG.text(false).units, "world units per value unit");
        assert_eq!(Channel::Field(1).text(true), mdtf_pack::texts::FIELD);
        assert_eq!(Channel::Jacobian { field: 0, axis: 1 }.text(true).units, "per world unit");
    }

    #[test]
    fn a_traced_channel_reaches_through_the_kernel_the_prefilter_and_the_ray() {
        // central4 reads 2 voxels each side; d_max 15 mm on 1 x 1 x 2.5 mm voxels
        let reach = Reach::new(Kernel::Central4, [3, 3, 1], 15.0, [1.0, 1.0, 2.5]);
        assert_eq!(reach.kernel, [2, 2, 2]);
        assert_eq!(reach.trace, [17, 17, 8]);
        assert_eq!(Channel::Distance.halo(false, &reach), [22, 22, 11]);
        assert_eq!(Channel::G.halo(false, &reach), [2, 2, 2]);
        assert_eq!(Channel::Value.halo(false, &reach), [0, 0, 0]);
        assert_eq!(Channel::InvG.producer(true), Producer::DeriveFields(Item::InvG));
        assert_eq!(Channel::InvG.producer(false), Producer::Derive(Item::InvG));
    }

    #[test]
    fn every_derive_item_makes_table_channels_and_store_names_read_back() {
        for item in Item::ALL {
            for c in item.components() {
                let channel = Channel::of_store(c).unwrap_or_else(|| panic!("{item:?} makes {c}, not a table row"));
                assert_eq!(channel.name(&[]), *c);
            }
        }
        for c in TABLE.iter().map(|r| r.channel).chain([Channel::GPrefiltered, Channel::F2Prefiltered]) {
            assert_eq!(Channel::of_store(&c.name(&[])), Some(c));
            let json = serde_json::to_string(&c).unwrap();
            assert_eq!(serde_json::from_str::<Channel>(&json).unwrap(), c, "{json}");
        }
        assert_eq!(serde_json::to_string(&Channel::GPrefiltered).unwrap(), "\"g_prefiltered\"");
        assert!(serde_json::from_str::<Channel>("\"nope\"").is_err());
        // a user cannot ask for the run's own pre-filtered channels
        assert_eq!(Channel::parse("g_prefiltered", &[]), None);
    }
}
