//! A tiny document model rendered twice: as Markdown (`report.md`) and as a self-contained
//! HTML page (`report.html`, each picture embedded: its SVG inline, zoomable, unless the
//! PNG is the smaller, as for dense scatter charts). Keeping one model guarantees the two
//! reports say the same thing.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use base64::Engine as _;

use crate::analysis::AnalysisError;

/// One block of the report.
#[derive(Debug, Clone)]
pub enum Block {
    /// A heading of level 1–3.
    Heading(u8, String),
    /// A paragraph of plain text (Markdown `**bold**` is rendered in HTML too).
    Para(String),
    /// A verdict banner: (passed? None = no tolerance given, text).
    Verdict(Option<bool>, String),
    /// A table: header and rows.
    Table(Vec<String>, Vec<Vec<String>>),
    /// A picture: caption and PNG path (relative links in Markdown, embedded in HTML).
    Image(String, PathBuf),
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// `**x**` → `<b>x</b>` after escaping.
fn inline_html(s: &str) -> String {
    let e = esc(s);
    let mut out = String::new();
    for (i, part) in e.split("**").enumerate() {
        if i % 2 == 1 {
            let _ = write!(out, "<b>{part}</b>");
        } else {
            out.push_str(part);
        }
    }
    out
}

/// Render as Markdown; images link to their file names (they sit beside `report.md`).
pub fn markdown(blocks: &[Block]) -> String {
    let mut s = String::new();
    for b in blocks {
        match b {
            Block::Heading(l, t) => {
                let _ = writeln!(s, "{} {t}\n", "#".repeat(usize::from(*l)));
            }
            Block::Para(t) => {
                let _ = writeln!(s, "{t}\n");
            }
            Block::Verdict(_, t) => {
                let _ = writeln!(s, "> **{t}**\n");
            }
            Block::Table(h, rows) => {
                let cell = |c: &String| c.replace('|', "\\|");
                let _ = writeln!(
                    s,
                    "| {} |",
                    h.iter().map(cell).collect::<Vec<_>>().join(" | ")
                );
                let _ = writeln!(
                    s,
                    "|{}|",
                    h.iter().map(|_| "---").collect::<Vec<_>>().join("|")
                );
                for r in rows {
                    let _ = writeln!(
                        s,
                        "| {} |",
                        r.iter().map(cell).collect::<Vec<_>>().join(" | ")
                    );
                }
                s.push('\n');
            }
            Block::Image(cap, path) => {
                let name = path
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
                let _ = writeln!(s, "![{cap}]({name})\n");
            }
        }
    }
    s
}

/// Render as one self-contained HTML page.
pub fn html(title: &str, blocks: &[Block]) -> Result<String, AnalysisError> {
    let mut s = String::new();
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\n<style>\
body{{font-family:sans-serif;max-width:1040px;margin:2em auto;padding:0 1em;color:#222}}\
table{{border-collapse:collapse;margin:0.5em 0 1.2em}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}\
th{{background:#f2f2f2}}td:first-child,th:first-child{{text-align:left}}img,figure svg{{max-width:100%;height:auto;border:1px solid #ddd}}\
.v{{padding:0.6em 1em;font-size:1.2em;border-radius:4px}}.pass{{background:#d8f3dc}}.fail{{background:#ffd6d6}}.none{{background:#eef}}\
figure{{margin:1em 0}}figcaption{{color:#555}}</style></head><body>\n",
        esc(title)
    );
    for b in blocks {
        match b {
            Block::Heading(l, t) => {
                let _ = writeln!(s, "<h{l}>{}</h{l}>", inline_html(t));
            }
            Block::Para(t) => {
                let _ = writeln!(s, "<p>{}</p>", inline_html(t));
            }
            Block::Verdict(v, t) => {
                let class = match v {
                    Some(true) => "pass",
                    Some(false) => "fail",
                    None => "none",
                };
                let _ = writeln!(s, "<p class=\"v {class}\"><b>{}</b></p>", esc(t));
            }
            Block::Table(h, rows) => {
                s.push_str("<table><tr>");
                for c in h {
                    let _ = write!(s, "<th>{}</th>", esc(c));
                }
                s.push_str("</tr>\n");
                for r in rows {
                    s.push_str("<tr>");
                    for c in r {
                        let _ = write!(s, "<td>{}</td>", inline_html(c));
                    }
                    s.push_str("</tr>\n");
                }
                s.push_str("</table>\n");
            }
            Block::Image(cap, path) => {
                let bytes = std::fs::read(path).map_err(|e| AnalysisError::io(path, e))?;
                let svg = std::fs::read_to_string(path.with_extension("svg")).ok();
                // Base64 makes the PNG a third larger on the page.
                match svg.filter(|t| t.len() * 3 < bytes.len() * 4 && t.starts_with("<svg")) {
                    Some(svg) => {
                        let _ = writeln!(
                            s,
                            "<figure role=\"img\" aria-label=\"{0}\">{svg}<figcaption>{0}</figcaption></figure>",
                            esc(cap)
                        );
                    }
                    None => {
                        let b64 = base64::engine::general_purpose::STANDARD.encode(bytes);
                        let _ = writeln!(
                            s,
                            "<figure><img alt=\"{0}\" src=\"data:image/png;base64,{b64}\"><figcaption>{0}</figcaption></figure>",
                            esc(cap)
                        );
                    }
                }
            }
        }
    }
    s.push_str("</body></html>\n");
    Ok(s)
}

/// Write `text` to `path`.
pub fn write(path: &Path, text: &str) -> Result<(), AnalysisError> {
    std::fs::write(path, text).map_err(|e| AnalysisError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards both renderings: a table and bold text come out as Markdown and as escaped HTML.
    #[test]
    fn renders_markdown_and_html() {
        let blocks = vec![
            Block::Heading(1, "R <1>".into()),
            Block::Para("ratio **2.00**".into()),
            Block::Table(
                vec!["a".into(), "b".into()],
                vec![vec!["1".into(), "x<y".into()]],
            ),
        ];
        let md = markdown(&blocks);
        assert!(md.contains("# R <1>") && md.contains("| a | b |") && md.contains("|---|---|"));
        let h = html("t", &blocks).unwrap();
        assert!(
            h.contains("<h1>R &lt;1&gt;</h1>") && h.contains("<b>2.00</b>") && h.contains("x&lt;y")
        );
    }
}
