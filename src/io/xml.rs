//! A small element tree over quick-xml, for metadata files such as X3P's `main.xml`.
//!
//! Names are kept as local names (namespace prefixes dropped), so `p:ISO5436_2` and `ISO5436_2` are
//! the same element. Depth and element count are bounded so a hostile file cannot exhaust memory.

use quick_xml::events::Event;
use quick_xml::Reader;

use crate::error::{Error, Result};

/// Bound on nesting depth: real metadata files are a handful of levels deep.
const MAX_DEPTH: usize = 64;
/// Bound on elements; a DataList of one `Datum` per point can be large, so this is generous.
const MAX_ELEMENTS: usize = 50_000_000;
/// Bytes one parsed element holds at most while the tree is built (the struct, its short text, and
/// the slack of its parent's growing child list): the element count is also bounded by the memory budget.
const ELEMENT_BYTES: u64 = 256;

/// One XML element: local name, concatenated text and children (no reader needs attributes; they are
/// checked for well-formedness and dropped).
#[derive(Debug, Clone, Default)]
pub struct Element {
    /// Local name (no namespace prefix).
    pub name: String,
    /// Text directly inside this element (not its children's), trimmed.
    pub text: String,
    /// Child elements in document order.
    pub children: Vec<Element>,
}

impl Element {
    /// First child with local name `name`.
    pub fn child(&self, name: &str) -> Option<&Element> {
        self.children.iter().find(|c| c.name == name)
    }

    /// Follow a path of child names.
    pub fn path(&self, path: &[&str]) -> Option<&Element> {
        path.iter().try_fold(self, |e, n| e.child(n))
    }

    /// Trimmed text at `path`, `None` when the element is absent or empty.
    pub fn text_at(&self, path: &[&str]) -> Option<&str> {
        self.path(path).map(|e| e.text.as_str()).filter(|t| !t.is_empty())
    }
}

/// Parse a whole document and return its root element.
pub fn parse(text: &str) -> Result<Element> {
    let mut reader = Reader::from_str(text);
    reader.config_mut().trim_text(false);
    let mut stack: Vec<Element> = Vec::new();
    let mut root: Option<Element> = None;
    let mut count = 0usize;
    let budget = crate::budget::max_memory();
    let max_elements = MAX_ELEMENTS.min(usize::try_from(budget / ELEMENT_BYTES).unwrap_or(usize::MAX));
    let too_many = || {
        Error::new(
            crate::error::ErrorKind::TooLarge,
            format!(
                "XML has more than {max_elements} elements, beyond the memory budget of {} (--max-memory)",
                crate::budget::human(budget)
            ),
        )
    };
    loop {
        let ev = reader.read_event().map_err(|e| Error::corrupt(format!("XML error at byte {}: {e}", reader.buffer_position())))?;
        match ev {
            Event::Start(s) => {
                count += 1;
                if stack.len() >= MAX_DEPTH {
                    return Err(Error::corrupt("XML nests too deeply"));
                }
                if count > max_elements {
                    return Err(too_many());
                }
                stack.push(element_from(&s)?);
            }
            Event::Empty(s) => {
                count += 1;
                if count > max_elements {
                    return Err(too_many());
                }
                let e = element_from(&s)?;
                attach(&mut stack, &mut root, e)?;
            }
            Event::End(_) => {
                let mut e = stack.pop().ok_or_else(|| Error::corrupt("XML closes an element it never opened"))?;
                e.text = e.text.trim().to_string();
                attach(&mut stack, &mut root, e)?;
            }
            Event::Text(t) => {
                if let Some(top) = stack.last_mut() {
                    top.text.push_str(&t.xml10_content());
                }
            }
            Event::CData(c) => {
                if let Some(top) = stack.last_mut() {
                    top.text.push_str(&c.into_inner());
                }
            }
            Event::GeneralRef(r) => {
                let resolved = match r.resolve_char_ref() {
                    Ok(Some(ch)) => ch.to_string(),
                    _ => {
                        let name = r.xml10_content();
                        quick_xml::escape::resolve_predefined_entity(&name)
                            .map(str::to_string)
                            .ok_or_else(|| Error::corrupt(format!("XML uses the undefined entity &{name};")))?
                    }
                };
                if let Some(top) = stack.last_mut() {
                    top.text.push_str(&resolved);
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if !stack.is_empty() {
        return Err(Error::corrupt("XML ends before its elements are closed"));
    }
    root.ok_or_else(|| Error::corrupt("XML has no root element"))
}

fn element_from(s: &quick_xml::events::BytesStart<'_>) -> Result<Element> {
    let name = s.local_name().as_ref().to_string();
    for a in s.attributes() {
        a.map_err(|e| Error::corrupt(format!("XML attribute error in <{name}>: {e}")))?;
    }
    Ok(Element { name, text: String::new(), children: Vec::new() })
}

fn attach(stack: &mut [Element], root: &mut Option<Element>, e: Element) -> Result<()> {
    match stack.last_mut() {
        Some(parent) => parent.children.push(e),
        None => {
            if root.is_some() {
                return Err(Error::corrupt("XML has more than one root element"));
            }
            *root = Some(e);
        }
    }
    Ok(())
}

/// Escape text for element content or attribute values.
pub fn escape(s: &str) -> String {
    quick_xml::escape::escape(s).into_owned()
}
