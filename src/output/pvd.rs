//! The `.pvd` collection: the list of `(time, file)` that makes ParaView open the `.vtu` files
//! as one time series.
//!
//! vtkio 0.6 has no PVD writer: its `xml::DataSetType` knows the VTK XML data sets and their
//! parallel variants, not `type="Collection"`. The format is a few lines of XML, written here:
//!
//! ```xml
//! <?xml version="1.0"?>
//! <VTKFile type="Collection" version="0.1" byte_order="LittleEndian">
//!   <Collection>
//!     <DataSet timestep="0.03125" group="" part="0" file="solution_000001.vtu"/>
//!   </Collection>
//! </VTKFile>
//! ```
//!
//! Times are written exactly: Rust's shortest round-trip form of the f64 (`0.03125`), in
//! exponent form (`1e-9`) where the plain form would be long.

use std::fmt::Write as _;

/// The collection file of run `run_id` listing `entries` = `(time, file name)` in order.
///
/// The run id is an XML comment `<!-- run_id: ID -->` after the declaration: readers ignore
/// comments, and an unknown attribute of `<VTKFile>` is not something every reader is sure to
/// pass over.
pub(super) fn render(entries: &[(f64, String)], run_id: &str) -> String {
    let mut s = format!(
        "<?xml version=\"1.0\"?>\n<!-- run_id: {} -->\n\
         <VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  \
         <Collection>\n",
        comment_safe(run_id)
    );
    for (time, file) in entries {
        let _ = writeln!(
            s,
            "    <DataSet timestep=\"{}\" group=\"\" part=\"0\" file=\"{}\"/>",
            format_time(*time),
            super::vtu::escape_attr(file)
        );
    }
    s.push_str("  </Collection>\n</VTKFile>\n");
    s
}

/// Shortest round-trip decimal form of `t`: plain (`0.03125`) when that takes at most 20
/// characters, else exponent form (`1e-12`), which is just as exact.
fn format_time(t: f64) -> String {
    let plain = format!("{t}");
    if plain.len() <= 20 {
        plain
    } else {
        format!("{t:e}")
    }
}

pub(super) fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

/// Reads back the `(time, file)` entries of a collection written by [`render`] (or any `.pvd`
/// whose `DataSet` elements carry `timestep` and `file` attributes). Errors say what is wrong.
pub(super) fn parse(text: &str) -> Result<Vec<(f64, String)>, String> {
    if !text.contains("type=\"Collection\"") {
        return Err("not a VTK collection (.pvd) file".into());
    }
    let mut entries = Vec::new();
    let mut rest = text;
    while let Some(start) = rest.find("<DataSet") {
        let after = &rest[start + "<DataSet".len()..];
        let end = after
            .find('>')
            .ok_or_else(|| "unterminated <DataSet> element".to_string())?;
        let attrs = &after[..end];
        let timestep = attribute(attrs, "timestep")
            .ok_or_else(|| format!("<DataSet{attrs}> has no timestep"))?;
        let time: f64 = timestep
            .parse()
            .map_err(|_| format!("timestep=\"{timestep}\" is not a number"))?;
        let file =
            attribute(attrs, "file").ok_or_else(|| format!("<DataSet{attrs}> has no file"))?;
        entries.push((time, unescape(file)));
        rest = &after[end..];
    }
    Ok(entries)
}

/// `id` as it stands in the comment: `--` may not occur inside an XML comment.
pub(super) fn comment_safe(id: &str) -> String {
    id.replace("--", "- -")
}

/// The run id of a collection written by [`render`] (as [`comment_safe`] made it).
pub(super) fn run_id(text: &str) -> Option<&str> {
    let start = text.find("<!-- run_id: ")? + "<!-- run_id: ".len();
    let len = text[start..].find(" -->")?;
    Some(&text[start..start + len])
}

/// The value of attribute `name` in the attribute text of an element.
fn attribute<'a>(attrs: &'a str, name: &str) -> Option<&'a str> {
    let mut rest = attrs;
    loop {
        let at = rest.find(name)?;
        let before_ok = at == 0 || rest[..at].ends_with(char::is_whitespace);
        let tail = rest[at + name.len()..].trim_start();
        if before_ok {
            if let Some(tail) = tail.strip_prefix('=') {
                let tail = tail.trim_start();
                let quote = tail.chars().next()?;
                if quote == '"' || quote == '\'' {
                    let value = &tail[1..];
                    return value.find(quote).map(|e| &value[..e]);
                }
            }
        }
        rest = &rest[at + name.len()..];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_then_parse_round_trips_times_exactly() {
        let entries = vec![
            (0.0, "solution_000000.vtu".to_string()),
            (0.03125, "solution_000001.vtu".to_string()),
            (0.1 + 0.2, "solution_000002.vtu".to_string()),
            (1e-12, "solution_000003.vtu".to_string()),
            (1.0 / 3.0, "solution_000004.vtu".to_string()),
            (1e22, "solution_000005.vtu".to_string()),
        ];
        let text = render(&entries, "abc");
        assert_eq!(run_id(&text), Some("abc"));
        assert!(text.contains(
            "<DataSet timestep=\"0.03125\" group=\"\" part=\"0\" file=\"solution_000001.vtu\"/>"
        ));
        let back = parse(&text).unwrap();
        assert_eq!(back.len(), entries.len());
        for ((t, f), (t2, f2)) in entries.iter().zip(&back) {
            assert_eq!(t.to_bits(), t2.to_bits());
            assert_eq!(f, f2);
        }
    }

    #[test]
    fn parse_refuses_other_files() {
        assert!(parse("<VTKFile type=\"UnstructuredGrid\"/>").is_err());
        let bad = "<VTKFile type=\"Collection\"><Collection><DataSet file=\"a.vtu\"/></Collection></VTKFile>";
        assert!(parse(bad).unwrap_err().contains("timestep"));
    }

    #[test]
    fn escape_round_trips() {
        let s = "a&b<c>\"d'";
        assert_eq!(unescape(&super::super::vtu::escape_attr(s)), s);
    }
}
