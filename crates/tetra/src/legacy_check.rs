//! Plain-words explanations of malformed ASCII legacy VTK files. The parser
//! reports most faults as "Parse error: Digit"; when it fails, this walks
//! the file's sections (POINTS, CELLS with or without OFFSETS and
//! CONNECTIVITY, CELL_TYPES, POINT_DATA / CELL_DATA with SCALARS, VECTORS
//! and NORMALS) and names the first count, index or number that is wrong.

/// Tokens of the data part, with the line each is on.
struct Tokens<'a> {
    items: Vec<(&'a str, usize)>,
    at: usize,
}

impl<'a> Tokens<'a> {
    fn next(&mut self) -> Option<(&'a str, usize)> {
        let t = self.items.get(self.at).copied();
        self.at += 1;
        t
    }
    fn left(&self) -> usize {
        self.items.len().saturating_sub(self.at)
    }
    /// A whole-number count after a keyword.
    fn count(&mut self, what: &str) -> Result<usize, String> {
        let (t, line) = self.next().ok_or_else(|| format!("{what} has no count"))?;
        t.parse::<usize>().map_err(|_| format!("line {line}: {what} count '{t}' is not a whole number"))
    }
    /// `n` numbers, each checked by `check` (index, text) -> problem.
    fn numbers(&mut self, what: &str, n: usize, check: &dyn Fn(usize, &str) -> Option<String>) -> Result<(), String> {
        if n > self.left() {
            return Err(format!(
                "{what} needs {n} numbers but only {} values follow in the file (a count larger than the data, or a truncated file)",
                self.left()
            ));
        }
        for i in 0..n {
            let (t, line) = self.next().unwrap_or(("", 0));
            if is_keyword(t) {
                return Err(format!(
                    "{what} needs {n} numbers but only {i} come before {t} on line {line} (a count larger than the data?)"
                ));
            }
            if let Some(problem) = check(i, t) {
                return Err(format!("line {line}: {what}: {problem}"));
            }
        }
        Ok(())
    }
}

/// A section keyword (POINTS, CELL_TYPES, ...) where a number was due.
fn is_keyword(t: &str) -> bool {
    t.len() > 3 && t.chars().all(|c| c.is_ascii_uppercase() || c == '_')
}

fn finite(_: usize, t: &str) -> Option<String> {
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => None,
        _ => Some(format!("'{t}' is not a finite number")),
    }
}

fn whole(_: usize, t: &str) -> Option<String> {
    t.parse::<i64>().is_err().then(|| format!("'{t}' is not a whole number"))
}

/// The first problem found in an ASCII legacy VTK text, if any can be named.
pub(crate) fn explain(text: &str) -> Option<String> {
    let mut lines = text.lines();
    let first = lines.next().unwrap_or("");
    if !first.starts_with("# vtk DataFile Version") {
        return Some("the first line must be '# vtk DataFile Version x.y' (is this a legacy VTK file?)".into());
    }
    let _title = lines.next();
    let format = lines.next().unwrap_or("").trim().to_ascii_uppercase();
    if format == "BINARY" {
        return None;
    }
    if format != "ASCII" {
        return Some(format!("line 3 must be ASCII or BINARY, not '{format}'"));
    }
    let items: Vec<(&str, usize)> =
        text.lines().enumerate().skip(3).flat_map(|(n, l)| l.split_whitespace().map(move |t| (t, n + 1))).collect();
    let mut t = Tokens { items, at: 0 };
    walk(&mut t).err()
}

fn walk(t: &mut Tokens) -> Result<(), String> {
    let mut points = None::<usize>;
    let mut cells = None::<usize>;
    let mut data_count = 0usize;
    let mut types = false;
    while let Some((key, line)) = t.next() {
        match key.to_ascii_uppercase().as_str() {
            "DATASET" => {
                let kind = t.next().map_or("", |(k, _)| k);
                if !kind.eq_ignore_ascii_case("UNSTRUCTURED_GRID") {
                    return Err(format!("line {line}: DATASET {kind}: only UNSTRUCTURED_GRID holds a mesh"));
                }
            }
            "POINTS" => {
                let n = t.count("POINTS")?;
                t.next(); // the type
                t.numbers(&format!("POINTS {n}"), n.saturating_mul(3), &finite)?;
                points = Some(n);
            }
            "CELLS" => {
                let n = t.count("CELLS")?;
                let size = t.count("CELLS")?;
                let np = points.ok_or_else(|| format!("line {line}: CELLS comes before POINTS"))?;
                let in_range = |_: usize, s: &str| match s.parse::<i64>() {
                    Ok(i) if i >= 0 && (i as u64) < np as u64 => None,
                    Ok(i) => Some(format!(
                        "point index {i} is out of range (the file has {np} points, 0 to {})",
                        np.saturating_sub(1)
                    )),
                    Err(_) => Some(format!("'{s}' is not a point index")),
                };
                if t.items.get(t.at).is_some_and(|(k, _)| k.eq_ignore_ascii_case("OFFSETS")) {
                    // version 5: CELLS offsets connectivity, then two arrays
                    t.next();
                    t.next();
                    t.numbers("OFFSETS", n, &whole)?;
                    let (k, l) = t.next().unwrap_or(("", line));
                    if !k.eq_ignore_ascii_case("CONNECTIVITY") {
                        return Err(format!("line {l}: expected CONNECTIVITY after the {n} offsets, found '{k}'"));
                    }
                    t.next();
                    t.numbers("CONNECTIVITY", size, &in_range)?;
                    cells = Some(n.saturating_sub(1));
                } else {
                    if size > t.left() {
                        return Err(format!(
                            "line {line}: CELLS {n} {size} needs {size} numbers but only {} values follow",
                            t.left()
                        ));
                    }
                    let mut used = 0usize;
                    for c in 0..n {
                        let (k, l) = t.next().unwrap_or(("", line));
                        if is_keyword(k) {
                            return Err(format!(
                                "CELLS {n} {size} announces {n} cells but only {c} come before {k} on line {l}"
                            ));
                        }
                        let per: usize =
                            k.parse().map_err(|_| format!("line {l}: cell {c}: '{k}' is not a point count"))?;
                        used = used.saturating_add(1).saturating_add(per);
                        if used > size {
                            return Err(format!(
                                "line {l}: cell {c} goes past the {size} numbers CELLS {n} {size} announces"
                            ));
                        }
                        t.numbers(&format!("cell {c}"), per, &in_range)?;
                    }
                    if used != size {
                        return Err(format!(
                            "line {line}: CELLS {n} {size} announces {size} numbers, the cells hold {used}"
                        ));
                    }
                    cells = Some(n);
                }
            }
            "CELL_TYPES" => {
                let n = t.count("CELL_TYPES")?;
                if let Some(c) = cells
                    && c != n
                {
                    return Err(format!("line {line}: CELL_TYPES {n}, but CELLS has {c} cells"));
                }
                t.numbers(&format!("CELL_TYPES {n}"), n, &whole)?;
                types = true;
            }
            "POINT_DATA" | "CELL_DATA" => {
                let n = t.count(key)?;
                let (expected, what) =
                    if key.eq_ignore_ascii_case("POINT_DATA") { (points, "points") } else { (cells, "cells") };
                if let Some(e) = expected
                    && e != n
                {
                    return Err(format!("line {line}: {key} {n}, but the file has {e} {what}"));
                }
                data_count = n;
            }
            "SCALARS" => {
                let (name, _) = t.next().unwrap_or(("", line));
                t.next(); // the type
                let mut comps = 1usize;
                if let Some((k, _)) = t.items.get(t.at).copied()
                    && let Ok(c) = k.parse::<usize>()
                {
                    comps = c;
                    t.next();
                }
                if t.items.get(t.at).is_some_and(|(k, _)| k.eq_ignore_ascii_case("LOOKUP_TABLE")) {
                    t.next();
                    t.next();
                }
                t.numbers(&format!("SCALARS {name}"), data_count.saturating_mul(comps), &finite)?;
            }
            "VECTORS" | "NORMALS" => {
                let (name, _) = t.next().unwrap_or(("", line));
                t.next();
                t.numbers(&format!("{key} {name}"), data_count.saturating_mul(3), &finite)?;
            }
            // sections not walked here: nothing more can be named with confidence
            _ => return Ok(()),
        }
    }
    match (points, cells, types) {
        (None, _, _) => Err("the file ends before its POINTS section (truncated?)".into()),
        (Some(_), None, _) => Err("the file ends before its CELLS section (truncated?)".into()),
        (Some(_), Some(_), false) => Err("the file ends before its CELL_TYPES section (truncated?)".into()),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\n";

    fn mesh(points: &str, cells: &str) -> String {
        format!(
            "{HEAD}{points}{cells}CELL_TYPES 1\n10\nPOINT_DATA 4\nSCALARS s float 1\nLOOKUP_TABLE default\n1 2 3 4\n"
        )
    }

    #[test]
    fn each_fault_is_named_in_words() {
        let pts = "POINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n";
        assert_eq!(explain(&mesh(pts, "CELLS 1 5\n4 0 1 2 3\n")), None);
        let cases = [
            (
                mesh(&pts.replace("POINTS 4", "POINTS 9"), "CELLS 1 5\n4 0 1 2 3\n"),
                "POINTS 9 needs 27 numbers but only 12 come before CELLS",
            ),
            (mesh(pts, "CELLS 1 5\n4 0 1 2 -1\n"), "point index -1 is out of range"),
            (mesh(pts, "CELLS 1 5\n4 0 1 2 9\n"), "point index 9 is out of range (the file has 4 points"),
            (
                mesh(&pts.replace("0 1 0 0 0 1", "0 nan 0 0 0 1"), "CELLS 1 5\n4 0 1 2 3\n"),
                "'nan' is not a finite number",
            ),
            (mesh(&pts.replace("POINTS 4", "POINTS 999999999999"), ""), "needs 2999999999997 numbers"),
            (mesh(pts, "CELLS 2 10\n4 0 1 2 3\n"), "announces 2 cells but only 1 come before CELL_TYPES"),
            (mesh(pts, "CELLS 1 6\n4 0 1 2 3\n"), "announces 6 numbers, the cells hold 5"),
            (
                mesh(pts, "CELLS 1 5\n4 0 1 2 3\n").replace("POINT_DATA 4", "POINT_DATA 5"),
                "POINT_DATA 5, but the file has 4 points",
            ),
            (
                mesh(pts, "CELLS 1 5\n4 0 1 2 3\n").replace("CELL_TYPES 1", "CELL_TYPES 2"),
                "CELL_TYPES 2, but CELLS has 1 cells",
            ),
            (mesh(pts, "CELLS x 5\n"), "CELLS count 'x' is not a whole number"),
            (mesh(pts, "CELLS 1 5\n18446744073709551615 0 1 2 3\n"), "cell 0 goes past the 5 numbers"),
        ];
        for (text, want) in cases {
            let got = explain(&text).unwrap_or_default();
            assert!(got.contains(want), "wanted '{want}', got '{got}'");
        }
        assert!(explain("hello").unwrap().contains("first line"));
        assert!(explain(&format!("{HEAD}{pts}CELLS 1 5\n4 0 1 2 3\n")).unwrap().contains("ends before its CELL_TYPES"));
    }

    #[test]
    fn version_5_offsets_and_connectivity_are_walked() {
        let text = format!(
            "{HEAD}POINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 2 4\nOFFSETS vtktypeint64\n0 4\nCONNECTIVITY vtktypeint64\n0 1 2 7\nCELL_TYPES 1\n10\n"
        );
        assert!(explain(&text).unwrap().contains("point index 7 is out of range"));
    }
}
