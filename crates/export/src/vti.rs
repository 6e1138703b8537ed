//! A writer of VTK XML image data (`.vti`, format version 1.0): float32
//! point arrays, zlib-compressed in blocks, appended raw after the XML, with
//! the grid's origin, spacing and direction matrix (VTK 9 reads `Direction`).

use flate2::Compression;
use flate2::write::ZlibEncoder;
use mdtf_volume::Geometry;
use rayon::prelude::*;
use std::borrow::Cow;
use std::io::{Result, Write};

/// Uncompressed bytes per compressed block (VTK's readers accept any size).
const BLOCK_BYTES: usize = 1 << 20;

/// One point array: `components` interleaved float32 values per point, x fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct PointArray<'a> {
    /// Array name, as VTK and ParaView list it.
    pub name: String,
    /// Values per point (1: scalar, 3: vector, 4: RGBA).
    pub components: usize,
    /// `components` x points values (borrowed from a decoded channel, or owned).
    pub values: Cow<'a, [f32]>,
}

/// The array's values as the zlib blocks of VTK's compressed binary layout:
/// a UInt64 header (block count, block size, size of the last partial block
/// or 0, compressed size of each block) followed by the blocks.
fn compressed(values: &[f32]) -> Vec<u8> {
    let blocks: Vec<Vec<u8>> = values
        .par_chunks(BLOCK_BYTES / 4)
        .map(|chunk| {
            let bytes: Vec<u8> = chunk.iter().flat_map(|v| v.to_le_bytes()).collect();
            let mut z = ZlibEncoder::new(Vec::with_capacity(bytes.len() / 2), Compression::fast());
            // writing into a Vec cannot fail
            let _ = z.write_all(&bytes);
            z.finish().unwrap_or_default()
        })
        .collect();
    let mut out = Vec::new();
    let header = [blocks.len() as u64, BLOCK_BYTES as u64, ((values.len() * 4) % BLOCK_BYTES) as u64];
    for h in header.iter().copied().chain(blocks.iter().map(|b| b.len() as u64)) {
        out.extend_from_slice(&h.to_le_bytes());
    }
    for b in &blocks {
        out.extend_from_slice(b);
    }
    out
}

/// Formats numbers for XML attributes (shortest round-trip form).
fn join(values: impl IntoIterator<Item = f64>) -> String {
    values.into_iter().map(|v| format!("{v:?}")).collect::<Vec<_>>().join(" ")
}

/// Finite minimum and maximum of a component (VTK shows them as the range
/// without reading the data); (0, 0) when no value is finite.
fn component_range(values: &[f32], components: usize, c: usize) -> (f64, f64) {
    let (lo, hi) = values
        .iter()
        .skip(c)
        .step_by(components)
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if lo <= hi { (lo as f64, hi as f64) } else { (0.0, 0.0) }
}

/// Writes `arrays` on the grid `geometry` as a `.vti` document to `w`;
/// `active_scalars` names the array VTK colours by first.
pub fn write_vti(
    w: &mut dyn Write,
    geometry: &Geometry,
    arrays: &[PointArray],
    active_scalars: Option<&str>,
) -> Result<()> {
    let [nx, ny, nz] = geometry.dims;
    let extent = format!("0 {} 0 {} 0 {}", nx.saturating_sub(1), ny.saturating_sub(1), nz.saturating_sub(1));
    // Direction is row-major: world = origin + D (i sx, j sy, k sz), column a = axis a's direction
    let d = &geometry.directions;
    let direction = join((0..3).flat_map(|row| (0..3).map(move |col| d[col][row])));
    let encoded: Vec<Vec<u8>> = arrays.iter().map(|a| compressed(&a.values)).collect();
    writeln!(w, r#"<?xml version="1.0"?>"#)?;
    writeln!(
        w,
        r#"<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt64" compressor="vtkZLibDataCompressor">"#
    )?;
    writeln!(
        w,
        r#"  <ImageData WholeExtent="{extent}" Origin="{}" Spacing="{}" Direction="{direction}">"#,
        join(geometry.origin),
        join(geometry.spacing)
    )?;
    writeln!(w, r#"    <Piece Extent="{extent}">"#)?;
    match active_scalars {
        Some(name) => writeln!(w, r#"      <PointData Scalars="{}">"#, xml_escape(name))?,
        None => writeln!(w, "      <PointData>")?,
    }
    let mut offset = 0usize;
    for (a, bytes) in arrays.iter().zip(&encoded) {
        let ranges: Vec<(f64, f64)> = (0..a.components).map(|c| component_range(&a.values, a.components, c)).collect();
        let (lo, hi) = if a.components == 1 {
            ranges[0]
        } else {
            // VTK's range of a vector array is that of its magnitude; the per-component ranges are enough here
            ranges.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), r| (l.min(r.0), h.max(r.1)))
        };
        writeln!(
            w,
            r#"        <DataArray type="Float32" Name="{}" NumberOfComponents="{}" format="appended" RangeMin="{lo:?}" RangeMax="{hi:?}" offset="{offset}"/>"#,
            xml_escape(&a.name),
            a.components
        )?;
        offset += bytes.len();
    }
    writeln!(w, "      </PointData>")?;
    writeln!(w, "      <CellData>")?;
    writeln!(w, "      </CellData>")?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </ImageData>")?;
    write!(w, "  <AppendedData encoding=\"raw\">\n   _")?;
    for bytes in &encoded {
        w.write_all(bytes)?;
    }
    writeln!(w, "\n  </AppendedData>")?;
    writeln!(w, "</VTKFile>")?;
    Ok(())
}

/// `text` with the five XML special characters escaped.
fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;").replace('\'', "&apos;")
}

#[cfg(test)]
mod tests {
    use super::*;
    use flate2::read::ZlibDecoder;
    use std::io::Read;

    /// Decodes one appended array by the layout VTK documents, independently of `compressed`.
    fn decode(bytes: &[u8]) -> Vec<f32> {
        let word = |i: usize| u64::from_le_bytes(bytes[i * 8..i * 8 + 8].try_into().unwrap()) as usize;
        let (n, block, last) = (word(0), word(1), word(2));
        let mut at = (3 + n) * 8;
        let mut raw = Vec::new();
        for b in 0..n {
            let size = word(3 + b);
            let mut piece = Vec::new();
            ZlibDecoder::new(&bytes[at..at + size]).read_to_end(&mut piece).unwrap();
            let expected = if b + 1 == n && last != 0 { last } else { block };
            assert_eq!(piece.len(), expected, "block {b}");
            raw.extend(piece);
            at += size;
        }
        raw.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
    }

    #[test]
    fn blocks_decode_to_the_values_for_sizes_around_the_block_edge() {
        for n in [0usize, 1, BLOCK_BYTES / 4 - 1, BLOCK_BYTES / 4, BLOCK_BYTES / 4 + 1, 3 * BLOCK_BYTES / 4 + 7] {
            let values: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
            assert_eq!(decode(&compressed(&values)), values, "{n} values");
        }
    }

    #[test]
    fn direction_is_written_row_major_from_axis_columns() {
        let mut g = Geometry::new([2, 3, 4], [0.5, 1.0, 2.0]).with_origin([1.0, -2.0, 3.0]);
        // axis x points along world y, axis y along world -x
        g.directions = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let a = PointArray { name: "v<1>".into(), components: 1, values: vec![1.0; 24].into() };
        let mut out = Vec::new();
        write_vti(&mut out, &g, &[a], Some("v<1>")).unwrap();
        let text = String::from_utf8_lossy(&out);
        assert!(text.contains(r#"Direction="0.0 -1.0 0.0 1.0 0.0 0.0 0.0 0.0 1.0""#), "{text}");
        assert!(text.contains(r#"WholeExtent="0 1 0 2 0 3""#));
        assert!(text.contains(r#"Name="v&lt;1&gt;""#));
    }
}
