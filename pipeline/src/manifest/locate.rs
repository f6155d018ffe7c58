//! Where things are in a manifest: byte spans mapped to lines and columns,
//! the key at a position, the span of a key — so that every error names its
//! place.

use std::path::Path;

use toml::de::{DeTable, DeValue};

use super::ManifestError;

/// Maps byte spans to lines and columns and builds located errors.
pub(super) struct Locator<'a> {
    pub(super) text: &'a str,
    pub(super) file: &'a Path,
}

impl Locator<'_> {
    fn position(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        (line, column)
    }

    pub(super) fn error(
        &self,
        span: Option<std::ops::Range<usize>>,
        key: String,
        variant: Option<&str>,
        message: String,
    ) -> ManifestError {
        ManifestError {
            file: self.file.to_path_buf(),
            position: span.map(|s| self.position(s.start)),
            key,
            variant: variant.map(str::to_string),
            message,
        }
    }

    /// A toml error, with the key found from its position in `table`.
    pub(super) fn toml_error(
        &self,
        e: &toml::de::Error,
        table: Option<&DeTable>,
        variant: Option<&str>,
    ) -> ManifestError {
        let key = match (table, e.span()) {
            (Some(t), Some(span)) => key_at(t, span.start).join("."),
            _ => String::new(),
        };
        self.error(e.span(), key, variant, e.message().trim().to_string())
    }
}

/// The dotted path of the innermost key whose key or value span contains
/// `offset`. Header tables (`[stride]`) span only their header, so the whole
/// tree is searched rather than pruned by the parents' spans.
fn key_at(table: &DeTable, offset: usize) -> Vec<String> {
    let mut best: Option<(usize, Vec<String>)> = None;
    search_table(table, offset, &mut Vec::new(), &mut best);
    best.map(|(_, path)| path).unwrap_or_default()
}

type Found = Option<(usize, Vec<String>)>;

fn search_table(table: &DeTable, offset: usize, path: &mut Vec<String>, best: &mut Found) {
    for (key, value) in table.iter() {
        path.push(key.get_ref().to_string());
        for span in [key.span(), value.span()] {
            let hit = span.contains(&offset) || (span.end == offset && !span.is_empty());
            if hit && best.as_ref().is_none_or(|(len, _)| span.len() < *len) {
                *best = Some((span.len(), path.clone()));
            }
        }
        search_value(value.get_ref(), offset, path, best);
        path.pop();
    }
}

fn search_value(value: &DeValue, offset: usize, path: &mut Vec<String>, best: &mut Found) {
    match value {
        DeValue::Table(t) => search_table(t, offset, path, best),
        DeValue::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                path.push(i.to_string());
                search_value(item.get_ref(), offset, path, best);
                path.pop();
            }
        }
        _ => {}
    }
}

/// Whether `table` has `key`.
pub(super) fn has_key(table: &DeTable, key: &str) -> bool {
    table.iter().any(|(k, _)| k.get_ref() == key)
}

/// Whether `table` has a value at the dotted `path` (through tables only).
pub(super) fn has_path(table: &DeTable, path: &[&str]) -> bool {
    let Some((first, rest)) = path.split_first() else {
        return true;
    };
    match table.iter().find(|(k, _)| k.get_ref() == first) {
        None => false,
        Some(_) if rest.is_empty() => true,
        Some((_, value)) => match value.get_ref() {
            DeValue::Table(t) => has_path(t, rest),
            _ => false,
        },
    }
}

/// The span of the value at a dotted `path`, or of its nearest present
/// ancestor (a defaulted field has no span of its own).
pub(super) fn span_of(table: &DeTable, path: &[&str]) -> Option<std::ops::Range<usize>> {
    let (first, rest) = path.split_first()?;
    let (key, value) = table.iter().find(|(k, _)| k.get_ref() == first)?;
    let inner = match value.get_ref() {
        DeValue::Table(t) => span_of(t, rest),
        DeValue::Array(items) => rest.split_first().and_then(|(i, rest)| {
            let item = items.get(i.parse::<usize>().ok()?)?;
            match item.get_ref() {
                DeValue::Table(t) => span_of(t, rest).or(Some(item.span())),
                _ => Some(item.span()),
            }
        }),
        _ => None,
    };
    inner.or(Some(if rest.is_empty() {
        value.span()
    } else {
        key.span()
    }))
}
