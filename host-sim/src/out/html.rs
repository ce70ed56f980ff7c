//! The reports' Markdown as one self-contained HTML page (every PNG it references embedded as
//! a base64 data URI, so the page can be mailed or archived alone), and the check that the
//! Markdown's tables are valid (each row has the header's number of cells, each `|` block
//! parses as a table).

use anyhow::{bail, Context, Result};
use pulldown_cmark::{html, CowStr, Event, Options, Parser, Tag, TagEnd};
use std::path::Path;

const STYLE: &str =
    "body{font-family:sans-serif;max-width:1150px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #bbb;padding:3px 8px}\
th{background:#eee}td{text-align:right}td:first-child{text-align:left}img{max-width:100%}code{background:#f3f3f3}";

/// Standard base64 (RFC 4648, with padding) of `bytes`.
pub fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for (i, shift) in [18, 12, 6, 0].into_iter().enumerate() {
            if i <= chunk.len() {
                s.push(char::from(ABC[((n >> shift) & 63) as usize]));
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn options() -> Options {
    Options::ENABLE_TABLES
}

/// `md` as a whole HTML page titled `title`; image links relative to `dir` are embedded
/// (a missing image is an error: the page would be incomplete).
pub fn page(title: &str, md: &str, dir: &Path) -> Result<String> {
    let mut events = Vec::new();
    for ev in Parser::new_ext(md, options()) {
        events.push(match ev {
            Event::Start(Tag::Image {
                link_type,
                dest_url,
                title,
                id,
            }) if !dest_url.starts_with("data:") => {
                let path = dir.join(dest_url.as_ref());
                let bytes = crate::sim::input::files::read_bytes(
                    &path,
                    crate::sim::input::files::DATA_LIMIT,
                )
                .context("embedding a plot")?;
                Event::Start(Tag::Image {
                    link_type,
                    dest_url: CowStr::from(format!("data:image/png;base64,{}", base64(&bytes))),
                    title,
                    id,
                })
            }
            e => e,
        });
    }
    let mut body = String::new();
    html::push_html(&mut body, events.into_iter());
    let esc = title
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;");
    Ok(format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{esc}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n{body}</body>\n</html>\n"
    ))
}

/// Cells of a table row in Markdown source (`|` at the ends optional, `\|` escaped).
fn cells(line: &str) -> usize {
    let t = line.trim();
    let t = t.strip_prefix('|').unwrap_or(t);
    let t = t
        .strip_suffix('|')
        .filter(|x| !x.ends_with('\\'))
        .unwrap_or(t);
    let mut n = 1;
    let mut prev = ' ';
    for c in t.chars() {
        if c == '|' && prev != '\\' {
            n += 1;
        }
        prev = c;
    }
    n
}

/// Fails unless every table in `md` is valid: each block of lines `| ... |` parses as a table
/// (header, delimiter row), and every row has as many cells as the header. The error names
/// the line.
pub fn check_tables(md: &str) -> Result<()> {
    let mut tables = Vec::new(); // byte ranges of the parsed tables
    let mut start = None;
    for (ev, range) in Parser::new_ext(md, options()).into_offset_iter() {
        match ev {
            Event::Start(Tag::Table(_)) => start = Some(range.start),
            Event::End(TagEnd::Table) => {
                if let Some(s) = start.take() {
                    tables.push(s..range.end);
                }
            }
            _ => {}
        }
    }
    let mut offset = 0;
    let mut in_code = false;
    let mut header: Option<usize> = None;
    for (i, line) in md.split_inclusive('\n').enumerate() {
        let at = offset;
        offset += line.len();
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
        }
        // A row as this project writes them: `| a | b |` (a paragraph line may start with
        // `|x|`, an absolute value, without being one).
        let is_row = !in_code && line.trim().starts_with('|') && line.trim().ends_with('|');
        if !is_row {
            header = None;
            continue;
        }
        if !tables.iter().any(|r| r.contains(&at)) {
            bail!(
                "line {}: `{}` is not part of a table (missing the `|---|` row?)",
                i + 1,
                line.trim()
            );
        }
        let n = cells(line);
        match header {
            None => header = Some(n),
            Some(h) if h != n => bail!(
                "line {}: {n} cells, the table's header has {h}: `{}`",
                i + 1,
                line.trim()
            ),
            Some(_) => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (plain, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), enc);
        }
    }

    #[test]
    fn the_table_check_finds_bad_tables() {
        let good = "# t\n\n| a | b \\| c |\n|---|---:|\n| 1 | 2 |\n\ntext\n\n| x |\n|---|\n| y |\n";
        check_tables(good).unwrap();
        let short = "| a | b |\n|---|---|\n| 1 |\n";
        assert!(format!("{:#}", check_tables(short).unwrap_err())
            .contains("line 3: 1 cells, the table's header has 2"));
        let no_delim = "| a | b |\n| 1 | 2 |\n";
        assert!(format!("{:#}", check_tables(no_delim).unwrap_err()).contains("line 1"));
        // A `|` line inside a code block, or a paragraph line starting with `|x|`, is no table.
        check_tables("```text\n| not a table |\n```\n").unwrap();
        check_tables("text\n|c| is its modulus\n").unwrap();
    }

    #[test]
    fn the_page_embeds_its_images() {
        let dir = std::env::temp_dir().join(format!("shimmy-html-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("p.png"), b"\x89PNG-bytes").unwrap();
        let html = page(
            "T <1>",
            "# T\n\n| a |\n|---|\n| 1 |\n\n![plot](p.png)\n",
            &dir,
        )
        .unwrap();
        assert!(html.contains("<title>T &lt;1&gt;</title>"));
        assert!(html.contains("<table>"));
        assert!(html.contains(&format!(
            "src=\"data:image/png;base64,{}\"",
            base64(b"\x89PNG-bytes")
        )));
        assert!(!html.contains("p.png"));
        let e = page("T", "![x](missing.png)\n", &dir).unwrap_err();
        assert!(format!("{e:#}").contains("missing.png"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
