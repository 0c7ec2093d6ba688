//! Rendering diagnostics for people, with miette's graphical report handler.

use std::fmt;

use miette::{
    GraphicalReportHandler, GraphicalTheme, LabeledSpan, MietteError, MietteSpanContents, Severity,
    SourceCode, SourceSpan, SpanContents,
};

use crate::diagnostic::{Diagnostic, Label};
use crate::source::{SourceMap, Span};

/// Text width of rendered reports; fixed so output does not depend on the terminal.
const WIDTH: usize = 100;

/// miette panics when it indents a marker past 65535 columns; labels further
/// right than this many bytes (a tab counts 4 columns) are reported without
/// the source snippet.
const MAX_SNIPPET_COLUMN: usize = 8_000;

/// Renders each diagnostic as a report: the code and message, then
/// `path:line:col` of the primary label, the source lines with the spans
/// marked, and the help. With `color: false` the output has no ANSI escapes and
/// is stable enough for snapshot tests.
pub fn render(diagnostics: &[Diagnostic], sources: &SourceMap, color: bool) -> String {
    let theme = if color {
        GraphicalTheme::unicode()
    } else {
        GraphicalTheme::unicode_nocolor()
    };
    // miette would print a byte column; the header is written into the source
    // name instead, so it shows the same character column as `location`.
    let handler = GraphicalReportHandler::new_themed(theme)
        .with_width(WIDTH)
        .without_primary_span_start();
    let mut out = String::new();
    for diagnostic in diagnostics {
        let mut rendered = String::new();
        let report = Report::new(diagnostic, sources);
        if !fits_a_snippet(diagnostic, sources)
            || handler.render_report(&mut rendered, &report).is_err()
        {
            rendered = render_without_snippet(diagnostic, sources);
        }
        if !out.is_empty() {
            out.push('\n');
        }
        out.push_str(&rendered);
    }
    out
}

fn fits_a_snippet(diagnostic: &Diagnostic, sources: &SourceMap) -> bool {
    diagnostic.labels.iter().all(|label| {
        let Some(file) = sources.try_get(label.span.file) else {
            return true;
        };
        [label.span.start, label.span.end]
            .into_iter()
            .all(|offset| {
                let offset = clamp_offset(&file.text, offset);
                let line_start = file.text[..offset]
                    .rfind('\n')
                    .map_or(0, |newline| newline + 1);
                offset - line_start <= MAX_SNIPPET_COLUMN
            })
    })
}

/// `path:line:col: error[code]: message`, and the help, for what miette cannot draw.
fn render_without_snippet(diagnostic: &Diagnostic, sources: &SourceMap) -> String {
    let mut rendered = format!(
        "{}: error[{}]: {}\n",
        location(diagnostic, sources),
        diagnostic.code,
        diagnostic.message
    );
    if let Some(help) = &diagnostic.help {
        rendered.push_str(&format!("  help: {help}\n"));
    }
    rendered
}

/// `path:line:col` of the diagnostic's primary label (1-based, columns in
/// characters), or `<unknown location>` when it has no label in `sources`.
pub fn location(diagnostic: &Diagnostic, sources: &SourceMap) -> String {
    diagnostic
        .labels
        .first()
        .and_then(|label| span_location(label.span, sources))
        .unwrap_or_else(|| "<unknown location>".to_string())
}

fn span_location(span: Span, sources: &SourceMap) -> Option<String> {
    let file = sources.try_get(span.file)?;
    let (line, column) = sources.line_col(span.file, clamp_offset(&file.text, span.start));
    Some(format!("{}:{line}:{column}", file.path.display()))
}

/// The largest char boundary not after `offset`, so a bad span cannot make us slice mid-character.
fn clamp_offset(text: &str, offset: usize) -> usize {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    offset
}

/// A [`Diagnostic`] seen through miette's trait. Labels in other files than the
/// primary one become related reports, each with its own source and the
/// label's message as their message.
#[derive(Debug)]
struct Report<'s> {
    message: String,
    code: &'static str,
    help: Option<String>,
    severity: Severity,
    source: Option<NamedText<'s>>,
    labels: Vec<LabeledSpan>,
    related: Vec<Report<'s>>,
}

impl<'s> Report<'s> {
    fn new(diagnostic: &Diagnostic, sources: &'s SourceMap) -> Report<'s> {
        let primary_file = diagnostic.labels.first().map(|label| label.span.file);
        let (here, elsewhere): (Vec<&Label>, Vec<&Label>) = diagnostic
            .labels
            .iter()
            .partition(|label| Some(label.span.file) == primary_file);
        let related = elsewhere
            .into_iter()
            .map(|label| Report {
                message: label.message.clone(),
                code: diagnostic.code.as_str(),
                help: None,
                severity: Severity::Advice,
                source: named_source(label.span, sources),
                labels: labeled_span(label, sources, false, false)
                    .into_iter()
                    .collect(),
                related: Vec::new(),
            })
            .collect();
        Report {
            message: diagnostic.message.clone(),
            code: diagnostic.code.as_str(),
            help: diagnostic.help.clone(),
            severity: Severity::Error,
            source: diagnostic
                .labels
                .first()
                .and_then(|label| named_source(label.span, sources)),
            labels: here
                .iter()
                .enumerate()
                .filter_map(|(index, label)| labeled_span(label, sources, index == 0, true))
                .collect(),
            related,
        }
    }
}

/// The text of `span`'s file, named `path:line:col` of the span's start.
fn named_source(span: Span, sources: &SourceMap) -> Option<NamedText<'_>> {
    let file = sources.try_get(span.file)?;
    let name = span_location(span, sources)?;
    Some(NamedText {
        name,
        text: &file.text,
    })
}

/// Like miette's `NamedSource`, but borrowing the text: a file with thousands
/// of diagnostics is not copied for each.
#[derive(Debug)]
struct NamedText<'s> {
    name: String,
    text: &'s str,
}

impl SourceCode for NamedText<'_> {
    fn read_span<'a>(
        &'a self,
        span: &SourceSpan,
        context_lines_before: usize,
        context_lines_after: usize,
    ) -> Result<Box<dyn SpanContents<'a> + 'a>, MietteError> {
        let contents = self
            .text
            .read_span(span, context_lines_before, context_lines_after)?;
        Ok(Box::new(MietteSpanContents::new_named(
            self.name.clone(),
            contents.data(),
            *contents.span(),
            contents.line(),
            contents.column(),
            contents.line_count(),
        )))
    }
}

/// A label as a miette span, clamped into its file; `None` for an unknown file.
fn labeled_span(
    label: &Label,
    sources: &SourceMap,
    primary: bool,
    with_message: bool,
) -> Option<LabeledSpan> {
    let text = &sources.try_get(label.span.file)?.text;
    let start = clamp_offset(text, label.span.start);
    let end = clamp_offset(text, label.span.end).max(start);
    let message = (with_message && !label.message.is_empty()).then(|| label.message.clone());
    let span = (start, end - start);
    Some(if primary {
        LabeledSpan::new_primary_with_span(message, span)
    } else {
        LabeledSpan::new_with_span(message, span)
    })
}

impl fmt::Display for Report<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Report<'_> {}

impl miette::Diagnostic for Report<'_> {
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(self.code))
    }

    fn severity(&self) -> Option<Severity> {
        Some(self.severity)
    }

    fn help<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        self.help
            .as_ref()
            .map(|help| Box::new(help) as Box<dyn fmt::Display>)
    }

    fn source_code(&self) -> Option<&dyn SourceCode> {
        self.source.as_ref().map(|source| source as &dyn SourceCode)
    }

    fn labels(&self) -> Option<Box<dyn Iterator<Item = LabeledSpan> + '_>> {
        if self.labels.is_empty() {
            None
        } else {
            Some(Box::new(self.labels.iter().cloned()))
        }
    }

    fn related<'a>(&'a self) -> Option<Box<dyn Iterator<Item = &'a dyn miette::Diagnostic> + 'a>> {
        if self.related.is_empty() {
            None
        } else {
            Some(Box::new(
                self.related
                    .iter()
                    .map(|report| report as &dyn miette::Diagnostic),
            ))
        }
    }
}
