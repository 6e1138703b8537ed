//! A streaming writer of VTK XML unstructured grids (`.vtu`, inline base64
//! binary with a UInt64 byte-count header, as VTK, ParaView and meshio read
//! them). Arrays are encoded straight from the mesh, so writing a mesh of
//! 100 million tetrahedra costs no second copy of it in memory (vtkio's
//! writer builds the whole document, with 64-bit indices, in memory first).

use crate::mesh::{PointArray, TetMesh};
use base64::engine::general_purpose::STANDARD;
use base64::write::EncoderWriter;
use std::io::{Result, Write};

/// One DataArray's samples as little-endian bytes, produced in chunks.
enum Samples<'a> {
    F64(&'a [f64]),
    F32(&'a [f32]),
    Points(&'a [[f64; 3]]),
    Connectivity { tets: &'a [[u32; 4]], wide: bool },
    Offsets { count: usize, wide: bool },
    Types(usize),
}

impl Samples<'_> {
    fn byte_len(&self) -> u64 {
        (match self {
            Samples::F64(v) => v.len() * 8,
            Samples::F32(v) => v.len() * 4,
            Samples::Points(p) => p.len() * 24,
            Samples::Connectivity { tets, wide } => tets.len() * 4 * if *wide { 8 } else { 4 },
            Samples::Offsets { count, wide } => count * if *wide { 8 } else { 4 },
            Samples::Types(n) => *n,
        }) as u64
    }

    fn write(&self, w: &mut impl Write) -> Result<()> {
        const CHUNK: usize = 1 << 14;
        let mut buf: Vec<u8> = Vec::with_capacity(CHUNK * 32);
        let flush = |buf: &mut Vec<u8>, w: &mut dyn Write| -> Result<()> {
            w.write_all(buf)?;
            buf.clear();
            Ok(())
        };
        match self {
            Samples::F64(v) => {
                for c in v.chunks(CHUNK) {
                    c.iter().for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
                    flush(&mut buf, w)?;
                }
            }
            Samples::F32(v) => {
                for c in v.chunks(CHUNK) {
                    c.iter().for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
                    flush(&mut buf, w)?;
                }
            }
            Samples::Points(p) => {
                for c in p.chunks(CHUNK) {
                    c.iter().flatten().for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
                    flush(&mut buf, w)?;
                }
            }
            Samples::Connectivity { tets, wide } => {
                for c in tets.chunks(CHUNK) {
                    for &i in c.iter().flatten() {
                        if *wide {
                            buf.extend_from_slice(&(i as i64).to_le_bytes());
                        } else {
                            buf.extend_from_slice(&(i as i32).to_le_bytes());
                        }
                    }
                    flush(&mut buf, w)?;
                }
            }
            Samples::Offsets { count, wide } => {
                for start in (0..*count).step_by(CHUNK) {
                    for c in start..(start + CHUNK).min(*count) {
                        let end = 4 * (c as u64 + 1);
                        if *wide {
                            buf.extend_from_slice(&(end as i64).to_le_bytes());
                        } else {
                            buf.extend_from_slice(&(end as i32).to_le_bytes());
                        }
                    }
                    flush(&mut buf, w)?;
                }
            }
            Samples::Types(n) => {
                for start in (0..*n).step_by(CHUNK) {
                    buf.resize((start + CHUNK).min(*n) - start, 10); // VTK_TETRA
                    flush(&mut buf, w)?;
                }
            }
        }
        Ok(())
    }
}

/// Escapes text for an XML attribute value.
fn attr(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Writes one inline binary DataArray: the byte count (UInt64) and the
/// samples, base64-encoded as one stream.
fn data_array(w: &mut impl Write, ty: &str, name: &str, components: usize, samples: Samples) -> Result<()> {
    let comps = if components > 1 { format!(" NumberOfComponents=\"{components}\"") } else { String::new() };
    write!(w, "        <DataArray type=\"{ty}\" Name=\"{}\"{comps} format=\"binary\">\n          ", attr(name))?;
    {
        let mut enc = EncoderWriter::new(&mut *w, &STANDARD);
        enc.write_all(&samples.byte_len().to_le_bytes())?;
        samples.write(&mut enc)?;
        enc.finish()?;
    }
    writeln!(w, "\n        </DataArray>")
}

/// Writes `mesh` (its scalar at full precision when it came from a file,
/// every input array, then `added`) as a `.vtu` document to `w`.
pub fn write_vtu(
    w: &mut impl Write,
    mesh: &TetMesh,
    added: &[PointArray],
    added_f32: &[(&str, usize, &[f32])],
) -> Result<()> {
    // 32-bit indices whenever they fit, as VTK writes them: half the file
    let wide = mesh.points.len() >= i32::MAX as usize || mesh.tets.len().saturating_mul(4) >= i32::MAX as usize;
    let index = if wide { "Int64" } else { "Int32" };
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
    )?;
    writeln!(w, "  <UnstructuredGrid>")?;
    writeln!(w, "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">", mesh.points.len(), mesh.tets.len())?;
    writeln!(w, "      <PointData Scalars=\"{}\">", attr(&mesh.scalar_name))?;
    if !mesh.arrays.iter().any(|a| a.name == mesh.scalar_name) {
        data_array(w, "Float32", &mesh.scalar_name, 1, Samples::F32(&mesh.scalar))?;
    }
    for a in mesh.arrays.iter().chain(added) {
        data_array(w, "Float64", &a.name, a.components, Samples::F64(&a.values))?;
    }
    for (name, components, values) in added_f32 {
        data_array(w, "Float32", name, *components, Samples::F32(values))?;
    }
    writeln!(w, "      </PointData>")?;
    writeln!(w, "      <Points>")?;
    data_array(w, "Float64", "Points", 3, Samples::Points(&mesh.points))?;
    writeln!(w, "      </Points>")?;
    writeln!(w, "      <Cells>")?;
    data_array(w, index, "connectivity", 1, Samples::Connectivity { tets: &mesh.tets, wide })?;
    data_array(w, index, "offsets", 1, Samples::Offsets { count: mesh.tets.len(), wide })?;
    data_array(w, "UInt8", "types", 1, Samples::Types(mesh.tets.len()))?;
    writeln!(w, "      </Cells>")?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </UnstructuredGrid>")?;
    writeln!(w, "</VTKFile>")
}
