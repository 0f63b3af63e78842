//! The `$PhysicalNames` section of a gmsh MSH file.
//!
//! `mshio` 0.4 parses only `$MeshFormat`, `$Entities`, `$Nodes` and `$Elements` and skips every
//! other section, `$PhysicalNames` included, so this small reader takes the names from the raw
//! bytes. The section is ASCII text in binary files too (gmsh writes it before the binary
//! sections):
//!
//! ```text
//! $PhysicalNames
//! 3
//! 1 3 "Γ3,1"
//! 1 5 "top edge"
//! 2 10 "Ω"
//! $EndPhysicalNames
//! ```
//!
//! Each entry is `dim tag "name"`; the name is UTF-8 and may contain commas and spaces.

use super::raw::find_section;

/// One entry of `$PhysicalNames`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct PhysicalName {
    pub dim: i32,
    pub tag: i32,
    pub name: String,
}

/// Reads the `$PhysicalNames` section of `bytes` (the whole file). A file without the section
/// has no names (`Ok(vec![])`). `Err` carries a message describing what is malformed; the
/// caller adds the file name.
pub(crate) fn read_physical_names(bytes: &[u8]) -> Result<Vec<PhysicalName>, String> {
    let Some(start) = find_section(bytes, b"$PhysicalNames") else {
        return Ok(Vec::new());
    };
    let mut lines = Lines { bytes, pos: start };
    let count_line = lines
        .next()
        .ok_or("the $PhysicalNames section ends after its header")?;
    let count: usize = text(count_line)?
        .trim()
        .parse()
        .map_err(|_| "the $PhysicalNames section does not start with the number of names")?;
    let mut names = Vec::with_capacity(count.min(1 << 16));
    for i in 0..count {
        let line = lines.next().ok_or_else(|| {
            format!("the $PhysicalNames section ends after {i} of its {count} names")
        })?;
        let line = text(line)?;
        if line.trim_start().starts_with('$') {
            return Err(format!(
                "the $PhysicalNames section announces {count} names but has only {i}"
            ));
        }
        names.push(parse_entry(line)?);
    }
    match lines.next().map(text) {
        Some(Ok(l)) if l.trim() == "$EndPhysicalNames" => Ok(names),
        _ => Err(format!(
            "the $PhysicalNames section announces {count} names but is not closed by \
             $EndPhysicalNames after them"
        )),
    }
}

/// Parses `dim tag "name"`.
fn parse_entry(line: &str) -> Result<PhysicalName, String> {
    let bad = || format!("malformed $PhysicalNames entry '{line}' (expected: dim tag \"name\")");
    let rest = line.trim();
    let (dim, rest) = rest.split_once(char::is_whitespace).ok_or_else(bad)?;
    let (tag, rest) = rest
        .trim_start()
        .split_once(char::is_whitespace)
        .ok_or_else(bad)?;
    let dim: i32 = dim.parse().map_err(|_| bad())?;
    let tag: i32 = tag.parse().map_err(|_| bad())?;
    let quoted = rest.trim();
    let name = quoted
        .strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .ok_or_else(bad)?;
    Ok(PhysicalName {
        dim,
        tag,
        name: name.to_string(),
    })
}

fn text(line: &[u8]) -> Result<&str, String> {
    std::str::from_utf8(line).map_err(|_| {
        format!(
            "a $PhysicalNames line is not valid UTF-8: '{}'",
            String::from_utf8_lossy(line)
        )
    })
}

/// Lines of `bytes` from `pos`, without their `\n` / `\r\n`.
struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Iterator for Lines<'a> {
    type Item = &'a [u8];
    fn next(&mut self) -> Option<&'a [u8]> {
        if self.pos >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.pos..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        let line = &rest[..end];
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_utf8_names_with_commas_and_spaces() {
        let src = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n3\n1 3 \"Γ3,1\"\r\n\
                   1 5 \"top edge\"\n2 10 \"Ω\"\n$EndPhysicalNames\n$Entities\n";
        let names = read_physical_names(src.as_bytes()).unwrap();
        assert_eq!(names.len(), 3);
        assert_eq!(
            names[0],
            PhysicalName {
                dim: 1,
                tag: 3,
                name: "Γ3,1".into()
            }
        );
        assert_eq!(names[1].name, "top edge");
        assert_eq!((names[2].dim, names[2].tag), (2, 10));
    }

    #[test]
    fn missing_section_is_empty_and_bad_sections_are_errors() {
        assert!(
            read_physical_names(b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n")
                .unwrap()
                .is_empty()
        );
        assert!(read_physical_names(b"$PhysicalNames\n2\n1 1 \"a\"\n").is_err());
        assert!(read_physical_names(b"$PhysicalNames\n1\n1 x \"a\"\n$EndPhysicalNames\n").is_err());
        assert!(read_physical_names(b"$PhysicalNames\n1\n1 1 a\n$EndPhysicalNames\n").is_err());
    }
}
