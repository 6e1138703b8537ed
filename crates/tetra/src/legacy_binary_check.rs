//! Plain-words explanations of malformed BINARY legacy VTK files, whose
//! parser's word for a file cut short is "Parse error: Complete": walks the
//! sections (POINTS, CELLS with or without OFFSETS and CONNECTIVITY,
//! CELL_TYPES, POINT_DATA / CELL_DATA with SCALARS, VECTORS and NORMALS) and
//! names the first one whose binary data the file does not hold.

/// Bytes of one value of a legacy VTK type name, None for one not known here.
fn type_size(name: &str) -> Option<usize> {
    Some(match name.to_ascii_lowercase().as_str() {
        "bit" | "unsigned_char" | "char" | "vtktypeuint8" | "vtktypeint8" => 1,
        "short" | "unsigned_short" | "vtktypeint16" | "vtktypeuint16" => 2,
        "int" | "unsigned_int" | "float" | "vtktypeint32" | "vtktypeuint32" => 4,
        "long" | "unsigned_long" | "double" | "vtktypeint64" | "vtktypeuint64" => 8,
        _ => return None,
    })
}

/// A cursor over the file: text lines between blocks of binary data.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    line: usize,
}

impl<'a> Cursor<'a> {
    /// The next non-empty text line's words.
    fn words(&mut self) -> Option<Vec<&'a str>> {
        while self.at < self.bytes.len() {
            let end = self.bytes[self.at..].iter().position(|&b| b == b'\n').map_or(self.bytes.len(), |p| self.at + p);
            let text = std::str::from_utf8(&self.bytes[self.at..end]).unwrap_or("");
            self.at = (end + 1).min(self.bytes.len());
            self.line += 1;
            let words: Vec<&str> = text.split_whitespace().collect();
            if !words.is_empty() {
                return Some(words);
            }
        }
        None
    }

    /// Skips `n` bytes of binary data for `what`, or says how many are missing.
    fn skip(&mut self, what: &str, n: Option<usize>) -> Result<(), String> {
        let n = n.ok_or_else(|| format!("line {}: {what}: a count or type mdtf cannot size", self.line))?;
        let left = self.bytes.len() - self.at;
        if n > left {
            return Err(format!(
                "{what} needs {n} bytes of binary data after line {} but only {left} follow (a truncated file, or a count larger than the data)",
                self.line
            ));
        }
        self.at += n;
        Ok(())
    }
}

fn count(words: &[&str], k: usize) -> Option<usize> {
    words.get(k)?.parse().ok()
}

fn times(a: Option<usize>, b: Option<usize>) -> Option<usize> {
    a?.checked_mul(b?)
}

/// The first binary section the file does not hold in full, if any can be named.
pub(crate) fn explain(bytes: &[u8]) -> Option<String> {
    let mut c = Cursor { bytes, at: 0, line: 0 };
    // version, title, BINARY
    for _ in 0..3 {
        c.words()?;
    }
    let (mut points, mut cells, mut data) = (None, None, None::<usize>);
    while let Some(w) = c.words() {
        let key = w[0].to_ascii_uppercase();
        let line = c.line;
        let result = match key.as_str() {
            "DATASET" => Ok(()),
            "POINTS" => {
                points = count(&w, 1);
                let what = format!("POINTS {}", w.get(1).unwrap_or(&""));
                c.skip(&what, times(times(points, Some(3)), w.get(2).and_then(|t| type_size(t))))
            }
            "CELLS" => {
                let (n, size) = (count(&w, 1), count(&w, 2));
                let what = format!("CELLS {} {}", w.get(1).unwrap_or(&""), w.get(2).unwrap_or(&""));
                let at = (c.at, c.line);
                match c.words() {
                    Some(o) if o[0].eq_ignore_ascii_case("OFFSETS") => {
                        cells = n.and_then(|n| n.checked_sub(1));
                        let offsets =
                            c.skip(&format!("{what}: OFFSETS"), times(n, o.get(1).and_then(|t| type_size(t))));
                        match offsets.and_then(|()| {
                            c.words().ok_or_else(|| format!("{what}: no CONNECTIVITY after its OFFSETS"))
                        }) {
                            Err(why) => Err(why),
                            Ok(k) if k[0].eq_ignore_ascii_case("CONNECTIVITY") => c.skip(
                                &format!("{what}: CONNECTIVITY"),
                                times(size, k.get(1).and_then(|t| type_size(t))),
                            ),
                            Ok(_) => Err(format!("{what}: no CONNECTIVITY after its OFFSETS")),
                        }
                    }
                    _ => {
                        (c.at, c.line) = at;
                        cells = n;
                        c.skip(&what, times(size, Some(4)))
                    }
                }
            }
            "CELL_TYPES" => c.skip(&format!("CELL_TYPES {}", w.get(1).unwrap_or(&"")), times(count(&w, 1), Some(4))),
            "POINT_DATA" => {
                data = count(&w, 1).or(points);
                Ok(())
            }
            "CELL_DATA" => {
                data = count(&w, 1).or(cells);
                Ok(())
            }
            "SCALARS" => {
                let comps = count(&w, 3).unwrap_or(1);
                let size = w.get(2).and_then(|t| type_size(t));
                // the LOOKUP_TABLE line, when there is one, comes before the data
                let at = (c.at, c.line);
                if !c.words().is_some_and(|l| l[0].eq_ignore_ascii_case("LOOKUP_TABLE")) {
                    (c.at, c.line) = at;
                }
                c.skip(&format!("SCALARS {}", w.get(1).unwrap_or(&"")), times(times(data, Some(comps)), size))
            }
            "VECTORS" | "NORMALS" => c.skip(
                &format!("{key} {}", w.get(1).unwrap_or(&"")),
                times(times(data, Some(3)), w.get(2).and_then(|t| type_size(t))),
            ),
            // sections not walked here: nothing more can be named with confidence
            _ => return None,
        };
        if let Err(why) = result {
            return Some(if why.starts_with("line ") { why } else { format!("line {line}: {why}") });
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A binary legacy VTK tetrahedron (version 4 cells), big-endian as VTK writes it.
    fn tet() -> Vec<u8> {
        let mut b = b"# vtk DataFile Version 4.2\nt\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n".to_vec();
        for v in [0.0f32, 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1.] {
            b.extend(v.to_be_bytes());
        }
        b.extend(b"\nCELLS 1 5\n");
        for v in [4i32, 0, 1, 2, 3] {
            b.extend(v.to_be_bytes());
        }
        b.extend(b"\nCELL_TYPES 1\n");
        b.extend(10i32.to_be_bytes());
        b.extend(b"\nPOINT_DATA 4\nSCALARS s float 1\nLOOKUP_TABLE default\n");
        for v in [1.0f32, 2., 3., 4.] {
            b.extend(v.to_be_bytes());
        }
        b.push(b'\n');
        b
    }

    #[test]
    fn a_whole_file_passes_and_a_cut_one_names_its_section() {
        let whole = tet();
        assert_eq!(explain(&whole), None);
        // cut inside the point coordinates, the cells, the scalars
        for (cut, said) in [
            (100, "POINTS 4 needs 48 bytes"),
            (150, "CELLS 1 5 needs 20 bytes"),
            (whole.len() - 6, "SCALARS s needs 16 bytes"),
        ] {
            let why = explain(&whole[..cut]).unwrap_or_default();
            assert!(why.contains(said) && why.contains("only"), "cut at {cut}: {why}");
        }
        // a count larger than the data
        let mut more = whole.clone();
        let at = more.windows(8).position(|w| w == b"POINTS 4").unwrap();
        more.splice(at + 7..at + 8, *b"99");
        let why = explain(&more).unwrap_or_default();
        assert!(why.contains("POINTS 99 needs 1188 bytes"), "{why}");
    }
}
