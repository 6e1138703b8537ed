//! Lists of fixed-size numeric records serialised as one byte string of
//! little-endian fields. A histogram volume's part holds hundreds of
//! thousands of (bin, count) records: a binary format (CBOR) then copies
//! one byte string instead of encoding and decoding every number, and every
//! float keeps its bits.

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serializer};

/// A record of a packed list: its fields' little-endian bytes, `BYTES` in all.
pub(crate) trait Record: Sized {
    /// Bytes of one record.
    const BYTES: usize;
    /// Appends the record's bytes.
    fn put(&self, out: &mut Vec<u8>);
    /// The record in `bytes` (exactly `BYTES` long).
    fn get(bytes: &[u8]) -> Self;
}

/// The `N` bytes at `at` of `bytes` (a record's field).
fn field<const N: usize>(bytes: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&bytes[at..at + N]);
    out
}

/// A non-zero bin and its count.
impl Record for (u32, u64) {
    const BYTES: usize = 12;
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.0.to_le_bytes());
        out.extend_from_slice(&self.1.to_le_bytes());
    }
    fn get(b: &[u8]) -> Self {
        (u32::from_le_bytes(field(b, 0)), u64::from_le_bytes(field(b, 4)))
    }
}

/// A non-zero (v, g) bin, its count and two sums.
impl Record for (u32, u64, f64, f64) {
    const BYTES: usize = 28;
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.0.to_le_bytes());
        out.extend_from_slice(&self.1.to_le_bytes());
        out.extend_from_slice(&self.2.to_le_bytes());
        out.extend_from_slice(&self.3.to_le_bytes());
    }
    fn get(b: &[u8]) -> Self {
        let f = |at| f64::from_le_bytes(field(b, at));
        (u32::from_le_bytes(field(b, 0)), u64::from_le_bytes(field(b, 4)), f(12), f(20))
    }
}

/// `#[serde(with = "packed")]`: the records as one byte string.
pub(crate) fn serialize<R: Record, S: Serializer>(records: &[R], s: S) -> Result<S::Ok, S::Error> {
    let mut bytes = Vec::with_capacity(records.len() * R::BYTES);
    for r in records {
        r.put(&mut bytes);
    }
    serde_bytes::serialize(&bytes, s)
}

/// `#[serde(with = "packed")]`: the records of one byte string (an error
/// if its length is not a whole number of records).
pub(crate) fn deserialize<'de, R: Record, D: Deserializer<'de>>(d: D) -> Result<Vec<R>, D::Error> {
    let bytes = serde_bytes::ByteBuf::deserialize(d)?;
    if !bytes.len().is_multiple_of(R::BYTES) {
        let message = format!("{} bytes are not a whole number of {}-byte records", bytes.len(), R::BYTES);
        return Err(D::Error::custom(message));
    }
    Ok(bytes.chunks_exact(R::BYTES).map(R::get).collect())
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Lists {
        #[serde(with = "super")]
        counts: Vec<(u32, u64)>,
        #[serde(with = "super")]
        sums: Vec<(u32, u64, f64, f64)>,
    }

    #[test]
    fn records_keep_every_bit_and_cost_their_field_bytes_alone() {
        let counts: Vec<(u32, u64)> = (0..1000u32).map(|i| (i * 16_769 % 16_777_216, u64::from(i) << 33 | 7)).collect();
        let sums = vec![(3, 1, -0.0, f64::INFINITY), (u32::MAX, u64::MAX, f64::MIN_POSITIVE / 2.0, 1e300)];
        let lists = Lists { counts, sums };
        let mut bytes = Vec::new();
        ciborium::into_writer(&lists, &mut bytes).unwrap();
        // the fields' bytes plus a few of CBOR's headers: no per-number encoding
        assert!(bytes.len() <= 1000 * 12 + 2 * 28 + 32, "{} bytes", bytes.len());
        let back: Lists = ciborium::from_reader(bytes.as_slice()).unwrap();
        assert_eq!(back.counts, lists.counts);
        let bits = |s: &[(u32, u64, f64, f64)]| -> Vec<(u32, u64, u64, u64)> {
            s.iter().map(|&(i, c, g, h)| (i, c, g.to_bits(), h.to_bits())).collect()
        };
        assert_eq!(bits(&back.sums), bits(&lists.sums));
    }

    #[test]
    fn a_byte_string_cut_inside_a_record_is_refused() {
        #[derive(Serialize)]
        struct Raw {
            #[serde(with = "serde_bytes")]
            counts: Vec<u8>,
            #[serde(with = "serde_bytes")]
            sums: Vec<u8>,
        }
        let mut bytes = Vec::new();
        ciborium::into_writer(&Raw { counts: vec![0; 13], sums: vec![] }, &mut bytes).unwrap();
        let e = ciborium::from_reader::<Lists, _>(bytes.as_slice()).unwrap_err().to_string();
        assert!(e.contains("13 bytes are not a whole number of 12-byte records"), "{e}");
    }
}
