//! Parsing `.dpp` text into the spanned AST: [`parse_module`].
//!
//! pest recognises the text (`grammar.pest`); this module turns pest's pairs
//! into the AST and pest's errors into diagnostics worded for users. pest stops
//! at the first error, so a file that fails is parsed again item by item and the
//! first error of every broken item is reported.

use pest::error::{Error as PestError, ErrorVariant, InputLocation};
use pest::iterators::Pair;
use pest::Parser as _;

use crate::ast::{
    Arg, BinaryOp, Block, Call, Expr, ExprKind, FnItem, Ident, Item, Module, ParamItem,
    PipelineItem, Stmt, StmtKind, UnaryOp, UseItem,
};
use crate::diagnostic::{Code, Diagnostic};
use crate::source::{FileId, Span};
use crate::suggest::did_you_mean;

#[derive(pest_derive::Parser)]
#[grammar = "grammar.pest"]
struct DppGrammar;

/// Bracket nesting, block nesting (with `else if` chains) and expression height
/// beyond this are rejected with a diagnostic. No real pipeline comes close, and
/// unbounded depth would exhaust the stack while parsing or dropping the AST.
const MAX_NESTING: usize = 200;

const SYNTAX: Code = Code::Syntax;
const LITERAL: Code = Code::Literal;
const NESTING: Code = Code::Nesting;

const ITEM_KEYWORDS: [&str; 4] = ["use", "param", "fn", "pipeline"];
const KEYWORDS: [&str; 14] = [
    "use", "param", "fn", "pipeline", "out", "for", "in", "while", "if", "else", "break", "return",
    "true", "false",
];

/// Stack for the parsing thread. pest and the AST builder recurse once per
/// nesting level, with frames of up to ~20 KiB in unoptimised builds; this
/// leaves a wide margin at [`MAX_NESTING`].
const PARSER_STACK_BYTES: usize = 16 << 20;

/// Parses one `.dpp` file. Spans are byte offsets into `text`, tagged with `file`.
/// On failure every syntax error found is returned, sorted by position.
pub fn parse_module(file: FileId, text: &str) -> Result<Module, Vec<Diagnostic>> {
    // On its own thread, so that how deep a file may nest does not depend on
    // the caller's stack (a test thread has 2 MiB).
    std::thread::scope(|scope| {
        let parser = std::thread::Builder::new()
            .name("dpp-parser".into())
            .stack_size(PARSER_STACK_BYTES)
            .spawn_scoped(scope, || parse_on_this_thread(file, text));
        match parser {
            Ok(parser) => parser
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic)),
            Err(_) => parse_on_this_thread(file, text), // no thread to be had
        }
    })
}

fn parse_on_this_thread(file: FileId, text: &str) -> Result<Module, Vec<Diagnostic>> {
    if let Some(too_deep) = check_bracket_nesting(file, text) {
        return Err(vec![too_deep]);
    }
    // pest only records the literal tokens it expected (`}`, `,`, `in`, …) when
    // asked to; they make the messages precise. The setting is process-wide and
    // only this grammar uses pest.
    pest::set_error_detail(true);
    match DppGrammar::parse(Rule::file, text) {
        Ok(pairs) => {
            let mut builder = Builder::new(file, 0);
            let items = pairs.flat_map(|pair| builder.file(pair)).collect();
            if builder.diagnostics.is_empty() {
                Ok(Module { file, items })
            } else {
                Err(sorted(builder.diagnostics))
            }
        }
        Err(error) => Err(recover_item_by_item(file, text, &error)),
    }
}

fn sorted(mut diagnostics: Vec<Diagnostic>) -> Vec<Diagnostic> {
    diagnostics.sort_by_key(|d| d.labels.first().map(|l| (l.span.start, l.span.end)));
    diagnostics
}

/// Parses each item of a file that failed as a whole on its own, so that every
/// broken item reports its first error. Items start at lines whose first word
/// is `use`, `param`, `fn` or `pipeline`: those words start nothing else, so
/// this holds even when an earlier item lost a brace.
fn recover_item_by_item(
    file: FileId,
    text: &str,
    whole_file_error: &PestError<Rule>,
) -> Vec<Diagnostic> {
    let mut diagnostics = Vec::new();
    let starts = item_starts(text);
    let bounds = starts.iter().copied().zip(starts.iter().skip(1).copied());
    let last = starts.last().map(|&start| (start, text.len()));
    for (start, end) in bounds.chain(last) {
        let chunk = &text[start..end];
        match DppGrammar::parse(Rule::file, chunk) {
            Ok(pairs) => {
                // A chunk that parses can still hold literal or chain errors.
                let mut builder = Builder::new(file, start);
                pairs.for_each(|pair| drop(builder.file(pair)));
                diagnostics.extend(builder.diagnostics);
            }
            Err(error) => diagnostics.push(syntax_error(file, text, start, &error)),
        }
    }
    if diagnostics.is_empty() {
        // Splitting made every piece valid (it should not happen): report the
        // error of the whole file rather than nothing.
        diagnostics.push(syntax_error(file, text, 0, whole_file_error));
    }
    sorted(diagnostics)
}

/// Byte offsets where top-level pieces start: 0, then the first word of every
/// line that begins with an item keyword.
fn item_starts(text: &str) -> Vec<usize> {
    let mut starts = vec![0];
    let mut line_start = 0;
    for line in text.split_inclusive('\n') {
        let indent = line.len() - line.trim_start_matches([' ', '\t']).len();
        let word_start = line_start + indent;
        if word_start > 0
            && ITEM_KEYWORDS
                .iter()
                .any(|kw| starts_with_word(text, word_start, kw))
        {
            starts.push(word_start);
        }
        line_start += line.len();
    }
    starts
}

fn starts_with_word(text: &str, at: usize, word: &str) -> bool {
    text[at..].starts_with(word)
        && !text[at + word.len()..]
            .chars()
            .next()
            .is_some_and(is_ident_char)
}

/// `text`, cut short with `…` when it is too long to quote in a message.
fn shortened(text: &str) -> String {
    const MAX_QUOTED_CHARS: usize = 40;
    match text.char_indices().nth(MAX_QUOTED_CHARS) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_string(),
    }
}

/// Whether `text` holds only whitespace and comments.
fn is_trivia(text: &str) -> bool {
    let mut rest = text.trim_start();
    while let Some(comment) = rest.strip_prefix("//") {
        rest = comment
            .find('\n')
            .map_or("", |newline| comment[newline..].trim_start());
    }
    rest.is_empty()
}

fn is_ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The brackets `(){}` of `text` with their offsets, outside comments and strings.
fn brackets(text: &str) -> impl Iterator<Item = (usize, char)> + '_ {
    let mut chars = text.char_indices().peekable();
    std::iter::from_fn(move || {
        while let Some((offset, c)) = chars.next() {
            match c {
                '/' if chars.peek().is_some_and(|&(_, next)| next == '/') => {
                    while chars.next_if(|&(_, c)| c != '\n').is_some() {}
                }
                '"' => while chars.next_if(|&(_, c)| c != '\n' && c != '"').is_some() {},
                '(' | ')' | '{' | '}' => return Some((offset, c)),
                _ => {}
            }
        }
        None
    })
}

/// Rejects bracket nesting deeper than [`MAX_NESTING`] before pest recurses into it.
fn check_bracket_nesting(file: FileId, text: &str) -> Option<Diagnostic> {
    let mut depth = 0usize;
    for (offset, bracket) in brackets(text) {
        if matches!(bracket, '(' | '{') {
            depth += 1;
            if depth > MAX_NESTING {
                let span = Span::new(file, offset, offset + 1);
                let message = format!("brackets are nested more than {MAX_NESTING} levels deep");
                return Some(
                    Diagnostic::error(NESTING, message, span).with_primary_message("too deep here"),
                );
            }
        } else {
            depth = depth.saturating_sub(1);
        }
    }
    None
}

/// The offset of the last `{` in `text` that is not closed within it.
fn innermost_unclosed_brace(text: &str) -> Option<usize> {
    let mut open = Vec::new();
    for (offset, bracket) in brackets(text) {
        match bracket {
            '{' => open.push(offset),
            '}' => drop(open.pop()),
            _ => {}
        }
    }
    open.pop()
}

// ---- syntax errors ------------------------------------------------------------

/// Turns a pest error of a piece of `text` starting at `offset` into a diagnostic
/// such as "expected an expression, found `)`".
fn syntax_error(file: FileId, text: &str, offset: usize, error: &PestError<Rule>) -> Diagnostic {
    let (position, expected) = match &error.variant {
        ErrorVariant::CustomError { .. } => {
            // pest's only custom errors are its stack and call limits.
            let at = offset + error_start(error);
            return Diagnostic::error(
                NESTING,
                "the file is nested too deeply to parse",
                Span::new(file, at, at),
            );
        }
        ErrorVariant::ParsingError { positives, .. } => {
            let from_tokens = error.parse_attempts().and_then(|attempts| {
                let at = offset + attempts.max_position;
                let after_word = text[..at.min(text.len())].ends_with(is_ident_char);
                let expected = Expected::from_tokens(
                    attempts.expected_tokens().iter().map(ToString::to_string),
                    attempts.unexpected_tokens().iter().map(ToString::to_string),
                    after_word,
                );
                (!expected.is_empty()).then_some((attempts.max_position, expected))
            });
            from_tokens.unwrap_or_else(|| (error_start(error), Expected::from_rules(positives)))
        }
    };
    let mut position = (offset + position).min(text.len());
    let found = Found::at(text, position);
    if position == text.len() {
        // Point just after the last token rather than at a blank line past it.
        position = text.trim_end().len();
    }
    let span = Span::new(file, position, position + found.len);
    let mut diagnostic = Diagnostic::error(
        SYNTAX,
        format!(
            "expected {}, found {}",
            expected.describe(),
            found.description
        ),
        span,
    );
    let at_end_of_item =
        found.len == 0 || found.word.is_some_and(|word| ITEM_KEYWORDS.contains(&word));
    if at_end_of_item && expected.tokens.contains(&"}") {
        if let Some(brace) = innermost_unclosed_brace(&text[offset..position.max(offset)]) {
            let brace = offset + brace;
            diagnostic = diagnostic.with_label(
                Span::new(file, brace, brace + 1),
                "this `{` is never closed",
            );
        }
    }
    let bare_expression = matches!(text[position..].chars().next(), Some('(' | '<' | '.'));
    if expected.tokens == ["="] && bare_expression {
        diagnostic = diagnostic
            .with_help("a statement cannot be a bare expression; bind its result: `x = map<f>(…)`");
    }
    if let Some(word) = found.word {
        // Where a name was expected, or where the keyword is being bound (`in = 3`).
        let after_word = text[position + word.len()..].trim_start();
        let bound = after_word.starts_with('=') && !after_word.starts_with("==");
        if KEYWORDS.contains(&word) && (expected.name || expected.keyword_rejected && bound) {
            diagnostic = diagnostic.with_help(format!(
                "`{word}` is a keyword and cannot be used as a name"
            ));
        } else if expected.item {
            if let Some(keyword) = did_you_mean(word, ITEM_KEYWORDS) {
                diagnostic = diagnostic.with_help(format!("did you mean `{keyword}`?"));
            }
        }
    }
    diagnostic
}

fn error_start<R>(error: &PestError<R>) -> usize {
    match error.location {
        InputLocation::Pos(position) => position,
        InputLocation::Span((start, _)) => start,
    }
}

/// What the parser expected at an error, grouped into words a user knows.
#[derive(Default)]
struct Expected {
    item: bool,
    statement: bool,
    expression: bool,
    name: bool,
    string: bool,
    operator: bool,
    /// Punctuation and keywords, shown literally: `}`, `,`, `in`.
    tokens: Vec<&'static str>,
    /// A keyword stood where a name could have: pest tried a name and refused it.
    keyword_rejected: bool,
}

/// Tokens shown literally, in the order they are listed in a message.
const LITERAL_TOKENS: [&str; 10] = ["=", "in", "..", "if", "{", ",", ")", "}", "(", ":"];
/// Tokens that can only continue an expression; their presence means "an operator".
const OPERATOR_TOKENS: [&str; 14] = [
    "+", "*", "/", "%", "==", "!=", "<", "<=", ">", ">=", "&&", "||", "->", "→",
];

impl Expected {
    /// Classifies the literal tokens pest tried at the error position, and
    /// those it refused there (only keywords, refused as names). `after_word`:
    /// the position directly follows a name, which pest tried to extend; those
    /// letters are not what is missing.
    fn from_tokens(
        tokens: impl Iterator<Item = String>,
        refused: impl Iterator<Item = String>,
        after_word: bool,
    ) -> Expected {
        let mut expected = Expected::default();
        for token in refused {
            if KEYWORDS.contains(&token.as_str()) {
                expected.keyword_rejected = true;
                expected.name = true;
            }
        }
        let mut open_paren = false;
        let mut colon = false;
        let mut statement_keywords = 0;
        for token in tokens {
            match token.as_str() {
                "use" | "param" | "fn" | "pipeline" => expected.item = true,
                // All of them where a statement can start; `if` alone after `else`.
                "out" | "for" | "while" | "if" | "break" | "return" => statement_keywords += 1,
                // A literal can start here; `!`, `-`, digits and `(` also start
                // other things, but `true` is tried only where an expression can start.
                "true" | "false" => expected.expression = true,
                "a..z" | "A..Z" | "_" => expected.name |= !after_word,
                "\"" => expected.string = true,
                // `(` after a name (a call) and `:` after a name (a named argument)
                // are possible but rarely what is missing.
                "(" => open_paren = true,
                ":" => colon = true,
                token if OPERATOR_TOKENS.contains(&token) => expected.operator = true,
                token => {
                    if let Some(&literal) = LITERAL_TOKENS.iter().find(|&&t| t == token) {
                        expected.tokens.push(literal);
                    }
                }
            }
        }
        match statement_keywords {
            0 => {}
            1 => expected.tokens.push("if"),
            _ => expected.statement = true,
        }
        // Whitespace, comments, digits inside names, `;` (optional) and `else`
        // (optional) were ignored above; a lone `(` or `:` is worth naming.
        if expected.is_empty() {
            if open_paren {
                expected.tokens.push("(");
            }
            if colon {
                expected.tokens.push(":");
            }
        }
        expected.settle();
        expected
    }

    /// Classifies pest's rule names, when it gave no literal tokens.
    fn from_rules(rules: &[Rule]) -> Expected {
        let mut expected = Expected::default();
        for rule in rules {
            match rule {
                Rule::file
                | Rule::use_item
                | Rule::param_item
                | Rule::fn_item
                | Rule::pipeline_item => expected.item = true,
                Rule::block => expected.tokens.push("{"),
                Rule::fn_params => expected.tokens.push("("),
                Rule::kw_in => expected.tokens.push("in"),
                Rule::string | Rule::unterminated_string => expected.string = true,
                Rule::ident => expected.name = true,
                Rule::out_stmt
                | Rule::for_stmt
                | Rule::while_stmt
                | Rule::if_stmt
                | Rule::break_stmt
                | Rule::return_stmt
                | Rule::tuple_bind
                | Rule::bind
                | Rule::kw_out
                | Rule::kw_for
                | Rule::kw_while
                | Rule::kw_if
                | Rule::kw_break
                | Rule::kw_return => expected.statement = true,
                Rule::expr
                | Rule::or_expr
                | Rule::and_expr
                | Rule::compare
                | Rule::sum
                | Rule::product
                | Rule::prefix
                | Rule::postfix
                | Rule::paren
                | Rule::number
                | Rule::bool
                | Rule::call
                | Rule::arg
                | Rule::op_neg
                | Rule::op_not => expected.expression = true,
                Rule::arrow
                | Rule::field
                | Rule::args
                | Rule::functor
                | Rule::op_or
                | Rule::op_and
                | Rule::op_eq
                | Rule::op_ne
                | Rule::op_le
                | Rule::op_lt
                | Rule::op_ge
                | Rule::op_gt
                | Rule::op_add
                | Rule::op_sub
                | Rule::op_mul
                | Rule::op_div
                | Rule::op_rem => expected.operator = true,
                _ => {} // parts of words and strings, and the end of input
            }
        }
        expected.settle();
        expected
    }

    /// Drops what a broader expectation already covers.
    fn settle(&mut self) {
        // Where a statement may start, the previous one may also continue;
        // naming operators then only lengthens the message.
        if self.statement {
            self.operator = false;
        }
        if self.statement || self.expression || self.item {
            self.name = false;
        }
        let order = |token: &&str| LITERAL_TOKENS.iter().position(|t| t == token);
        self.tokens.sort_by_key(order);
        self.tokens.dedup();
    }

    fn is_empty(&self) -> bool {
        !(self.item
            || self.statement
            || self.expression
            || self.name
            || self.string
            || self.operator)
            && self.tokens.is_empty()
    }

    /// "a statement, `}` or an operator".
    fn describe(&self) -> String {
        let mut parts: Vec<String> = Vec::new();
        if self.item {
            parts.push("an item (`use`, `param`, `fn` or `pipeline`)".into());
        }
        if self.statement {
            parts.push("a statement".into());
        }
        if self.expression {
            parts.push("an expression".into());
        }
        if self.name {
            parts.push("a name".into());
        }
        if self.string {
            parts.push("a string".into());
        }
        parts.extend(self.tokens.iter().map(|token| format!("`{token}`")));
        if self.operator {
            parts.push("an operator".into());
        }
        match parts.split_last() {
            None => "something else".into(),
            Some((last, [])) => last.clone(),
            Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        }
    }
}

/// The token at an error position, described for a message.
struct Found<'t> {
    description: String,
    /// Byte length of the token, so the label marks all of it.
    len: usize,
    /// The token when it is a word (a name or a keyword).
    word: Option<&'t str>,
}

impl<'t> Found<'t> {
    fn at(text: &'t str, position: usize) -> Found<'t> {
        let rest = &text[position..];
        let Some(first) = rest.chars().next() else {
            return Found {
                description: "end of file".into(),
                len: 0,
                word: None,
            };
        };
        if first.is_ascii_alphanumeric() || first == '_' {
            let len = rest.find(|c: char| !is_ident_char(c)).unwrap_or(rest.len());
            let word = &rest[..len];
            let description = if KEYWORDS.contains(&word) {
                format!("keyword `{word}`")
            } else {
                format!("`{}`", shortened(word))
            };
            let word = (!first.is_ascii_digit()).then_some(word);
            return Found {
                description,
                len,
                word,
            };
        }
        if first == '"' {
            return Found {
                description: "a string".into(),
                len: 1,
                word: None,
            };
        }
        const MULTI_CHAR: [&str; 10] = ["->", "==", "!=", "<=", ">=", "&&", "||", "..", "//", "→"];
        let token = MULTI_CHAR
            .iter()
            .copied()
            .find(|token| rest.starts_with(token))
            .unwrap_or(&rest[..first.len_utf8()]);
        let description = if first.is_whitespace() || first.is_control() {
            format!("`{}`", first.escape_debug())
        } else {
            format!("`{token}`")
        };
        Found {
            description,
            len: token.len(),
            word: None,
        }
    }
}

// ---- building the AST -----------------------------------------------------------

/// An expression with the height of its tree, kept to bound the AST's depth.
struct Built {
    expr: Expr,
    height: usize,
}

/// Builds AST nodes from the pairs of one parsed piece of a file and collects
/// the errors pest cannot see (malformed literals, chains into non-calls, …).
struct Builder {
    file: FileId,
    /// Byte offset of the parsed piece inside the file.
    offset: usize,
    diagnostics: Vec<Diagnostic>,
    block_depth: usize,
    reported_too_deep: bool,
}

impl Builder {
    fn new(file: FileId, offset: usize) -> Builder {
        Builder {
            file,
            offset,
            diagnostics: Vec::new(),
            block_depth: 0,
            reported_too_deep: false,
        }
    }

    /// The pair's span without trailing whitespace and comments: pest counts
    /// the whitespace skipped before a repetition that then matched nothing
    /// (`expr = { or_expr ~ (arrow ~ or_expr)* }`) as part of the rule.
    fn span(&self, pair: &Pair<Rule>) -> Span {
        let input = pair.get_input();
        let mut end_pair = pair.clone();
        let end = loop {
            let end = end_pair.as_span().end();
            match end_pair.clone().into_inner().last() {
                Some(last) if is_trivia(&input[last.as_span().end()..end]) => end_pair = last,
                _ => break end,
            }
        };
        Span::new(
            self.file,
            self.offset + pair.as_span().start(),
            self.offset + end,
        )
    }

    fn report_too_deep(&mut self, span: Span, what: &str) {
        if !self.reported_too_deep {
            self.reported_too_deep = true;
            self.diagnostics.push(Diagnostic::error(
                NESTING,
                format!("{what} nested more than {MAX_NESTING} levels deep"),
                span,
            ));
        }
    }

    fn file(&mut self, pair: Pair<Rule>) -> Vec<Item> {
        pair.into_inner()
            .filter_map(|item| self.item(item))
            .collect()
    }

    fn item(&mut self, pair: Pair<Rule>) -> Option<Item> {
        let span = self.span(&pair);
        let rule = pair.as_rule();
        let mut parts = significant(pair);
        let item = match rule {
            Rule::use_item => {
                let path = parts.next()?;
                Item::Use(self.use_item(path, span))
            }
            Rule::param_item => {
                let name = self.ident(parts.next()?);
                let value = self.expr(parts.next()?);
                Item::Param(ParamItem { name, value, span })
            }
            Rule::fn_item => {
                let name = self.ident(parts.next()?);
                let params = parts
                    .next()?
                    .into_inner()
                    .map(|param| self.ident(param))
                    .collect();
                let body = self.block(parts.next()?);
                Item::Fn(FnItem {
                    name,
                    params,
                    body,
                    span,
                })
            }
            Rule::pipeline_item => {
                let name = self.ident(parts.next()?);
                let body = self.block(parts.next()?);
                Item::Pipeline(PipelineItem { name, body, span })
            }
            _ => return None, // end of input
        };
        Some(item)
    }

    fn use_item(&mut self, literal: Pair<Rule>, span: Span) -> UseItem {
        let path_span = self.span(&literal);
        let quoted = literal.as_str();
        if literal.as_rule() == Rule::unterminated_string {
            self.diagnostics.push(
                Diagnostic::error(SYNTAX, "unterminated string", path_span)
                    .with_primary_message("this string has no closing `\"`")
                    .with_help("a path ends with `\"` on the same line"),
            );
        }
        let unquoted = quoted.strip_prefix('"').unwrap_or(quoted);
        let path = match literal.as_rule() {
            Rule::string => unquoted.strip_suffix('"').unwrap_or(unquoted),
            _ => unquoted,
        }
        .to_string();
        UseItem {
            path,
            path_span,
            span,
        }
    }

    fn ident(&self, pair: Pair<Rule>) -> Ident {
        Ident {
            name: pair.as_str().to_string(),
            span: self.span(&pair),
        }
    }

    fn block(&mut self, pair: Pair<Rule>) -> Block {
        let span = self.span(&pair);
        if self.block_depth >= MAX_NESTING {
            self.report_too_deep(span, "blocks are");
            return Block {
                stmts: Vec::new(),
                span,
            };
        }
        self.block_depth += 1;
        let stmts = pair
            .into_inner()
            .filter_map(|stmt| self.stmt(stmt))
            .collect();
        self.block_depth -= 1;
        Block { stmts, span }
    }

    fn stmt(&mut self, pair: Pair<Rule>) -> Option<Stmt> {
        let span = self.span(&pair);
        let rule = pair.as_rule();
        if rule == Rule::if_stmt {
            return Some(self.if_stmt(pair));
        }
        let mut parts = significant(pair);
        let kind = match rule {
            Rule::bind => {
                let target = self.ident(parts.next()?);
                StmtKind::Bind {
                    targets: vec![target],
                    value: self.expr(parts.next()?),
                }
            }
            Rule::tuple_bind => {
                let mut targets = Vec::new();
                let mut value = None;
                for part in parts {
                    match part.as_rule() {
                        Rule::ident => targets.push(self.ident(part)),
                        _ => value = Some(self.expr(part)),
                    }
                }
                StmtKind::Bind {
                    targets,
                    value: value?,
                }
            }
            Rule::out_stmt => {
                let name = self.ident(parts.next()?);
                StmtKind::Out {
                    name,
                    value: parts.next().map(|value| self.expr(value)),
                }
            }
            Rule::for_stmt => {
                let var = self.ident(parts.next()?);
                let start = self.expr(parts.next()?);
                let end = self.expr(parts.next()?);
                StmtKind::For {
                    var,
                    start,
                    end,
                    body: self.block(parts.next()?),
                }
            }
            Rule::while_stmt => {
                let cond = self.expr(parts.next()?);
                StmtKind::While {
                    cond,
                    body: self.block(parts.next()?),
                }
            }
            Rule::break_stmt => StmtKind::Break,
            Rule::return_stmt => StmtKind::Return(self.expr(parts.next()?)),
            _ => return None, // a `;` separator
        };
        Some(Stmt { kind, span })
    }

    /// `if a {…} else if b {…} else {…}` becomes `if a {…} else { if b {…} else {…} }`;
    /// each nested `if` spans from its `if` keyword to the end of the whole chain.
    fn if_stmt(&mut self, pair: Pair<Rule>) -> Stmt {
        let span = self.span(&pair);
        let mut branches = Vec::new(); // (start of the `if`, condition pair, block pair)
        let mut final_else = None;
        let mut parts = significant(pair);
        let first_cond = parts.next();
        let first_block = parts.next();
        if let (Some(cond), Some(block)) = (first_cond, first_block) {
            branches.push((span.start, cond, block));
        }
        for part in parts {
            match part.as_rule() {
                Rule::else_if => {
                    let if_start = part
                        .clone()
                        .into_inner()
                        .find(|keyword| keyword.as_rule() == Rule::kw_if)
                        .map_or(self.span(&part).start, |keyword| self.span(&keyword).start);
                    let mut else_if = significant(part);
                    if let (Some(cond), Some(block)) = (else_if.next(), else_if.next()) {
                        branches.push((if_start, cond, block));
                    }
                }
                _ => final_else = Some(part),
            }
        }
        let allowed_branches = MAX_NESTING.saturating_sub(self.block_depth).max(1);
        if let Some(&(first_too_many, _, _)) = branches.get(allowed_branches) {
            let if_keyword = Span::new(self.file, first_too_many, first_too_many + "if".len());
            self.report_too_deep(if_keyword, "`else if` chains are");
            branches.truncate(1);
            final_else = None;
        }
        let mut else_block = final_else.map(|block| self.block(block));
        let mut built = None;
        while let Some((start, cond, block)) = branches.pop() {
            let cond = self.expr(cond);
            let then_block = self.block(block);
            let stmt = Stmt {
                kind: StmtKind::If {
                    cond,
                    then_block,
                    else_block: else_block.take(),
                },
                span: Span::new(self.file, start, span.end),
            };
            if branches.is_empty() {
                built = Some(stmt);
            } else {
                else_block = Some(Block {
                    span: stmt.span,
                    stmts: vec![stmt],
                });
            }
        }
        built.unwrap_or(Stmt {
            kind: StmtKind::Break,
            span,
        })
    }

    // ---- expressions ----

    fn expr(&mut self, pair: Pair<Rule>) -> Expr {
        self.expr_node(pair).expr
    }

    fn expr_node(&mut self, pair: Pair<Rule>) -> Built {
        // Precedence levels with a single operand add nothing: skip them without
        // recursing, so each bracket level costs few stack frames.
        let mut pair = pair;
        loop {
            let passes_through = matches!(
                pair.as_rule(),
                Rule::expr
                    | Rule::or_expr
                    | Rule::and_expr
                    | Rule::compare
                    | Rule::sum
                    | Rule::product
                    | Rule::prefix
                    | Rule::postfix
            );
            let mut inner = pair.clone().into_inner();
            match (passes_through, inner.next(), inner.next()) {
                (true, Some(only), None) => pair = only,
                _ => break,
            }
        }
        let span = self.span(&pair);
        match pair.as_rule() {
            Rule::expr => self.chain(pair),
            Rule::or_expr | Rule::and_expr | Rule::sum | Rule::product => self.binary_chain(pair),
            Rule::compare => self.comparison(pair),
            Rule::prefix => self.prefix(pair),
            Rule::postfix => self.postfix(pair),
            Rule::paren if pair.clone().into_inner().count() > 1 => {
                let elements: Vec<Built> = pair
                    .into_inner()
                    .map(|inner| self.expr_node(inner))
                    .collect();
                let height = elements.iter().map(|e| e.height).max().unwrap_or(0) + 1;
                Built {
                    expr: Expr {
                        kind: ExprKind::Tuple(elements.into_iter().map(|e| e.expr).collect()),
                        span,
                    },
                    height,
                }
            }
            Rule::paren => {
                let inner = pair.into_inner().next().map(|inner| self.expr_node(inner));
                // The parentheses belong to the expression's span.
                inner.map_or_else(
                    || self.placeholder(span),
                    |built| Built {
                        expr: Expr { span, ..built.expr },
                        ..built
                    },
                )
            }
            Rule::number => self.number(pair),
            Rule::bool => self.leaf(ExprKind::Bool(pair.as_str() == "true"), span),
            Rule::ident => self.leaf(ExprKind::Name(self.ident(pair)), span),
            Rule::call => self.call(pair),
            _ => self.placeholder(span),
        }
    }

    fn leaf(&self, kind: ExprKind, span: Span) -> Built {
        Built {
            expr: Expr { kind, span },
            height: 1,
        }
    }

    /// Stands in for an expression that had an error; the module is not returned then.
    fn placeholder(&self, span: Span) -> Built {
        self.leaf(ExprKind::Int(0), span)
    }

    fn node(&mut self, kind: ExprKind, span: Span, children_height: usize) -> Built {
        let height = children_height + 1;
        if height > MAX_NESTING {
            self.report_too_deep(span, "expressions are");
            return self.placeholder(span);
        }
        Built {
            expr: Expr { kind, span },
            height,
        }
    }

    /// `a → f → g(x)`: each arrow hands its left side to the call on its right.
    fn chain(&mut self, pair: Pair<Rule>) -> Built {
        let span = self.span(&pair);
        let mut parts = pair.into_inner();
        let Some(first) = parts.next() else {
            return self.placeholder(span);
        };
        let mut lhs = self.expr_node(first);
        while let (Some(arrow), Some(rhs)) = (parts.next(), parts.next()) {
            let rhs = self.expr_node(rhs);
            let span = lhs.expr.span.to(rhs.expr.span);
            let height = lhs.height.max(rhs.height);
            lhs = match rhs.expr.kind {
                ExprKind::Call(call) if call.piped.is_none() => {
                    let call = Call {
                        piped: Some(Box::new(lhs.expr)),
                        ..call
                    };
                    self.node(ExprKind::Call(call), span, height)
                }
                kind => {
                    self.report_chain_into_non_call(arrow.as_str(), &kind, rhs.expr.span);
                    lhs
                }
            };
        }
        lhs
    }

    fn report_chain_into_non_call(&mut self, arrow: &str, rhs: &ExprKind, rhs_span: Span) {
        let mut diagnostic = Diagnostic::error(
            SYNTAX,
            format!("the right side of `{arrow}` must be a primitive call"),
            rhs_span,
        )
        .with_primary_message("this is not a call");
        if let ExprKind::Name(name) = rhs {
            let name = &name.name;
            diagnostic = diagnostic.with_help(format!(
                "to apply a functor write `map<{name}>`; to call `{name}` write `{name}(…)`"
            ));
        }
        self.diagnostics.push(diagnostic);
    }

    /// Left-associative operators of one precedence level.
    fn binary_chain(&mut self, pair: Pair<Rule>) -> Built {
        let span = self.span(&pair);
        let mut parts = pair.into_inner();
        let Some(first) = parts.next() else {
            return self.placeholder(span);
        };
        let mut lhs = self.expr_node(first);
        while let (Some(op), Some(rhs)) = (parts.next(), parts.next()) {
            let rhs = self.expr_node(rhs);
            lhs = self.binary(&op, lhs, rhs);
        }
        lhs
    }

    fn binary(&mut self, op: &Pair<Rule>, lhs: Built, rhs: Built) -> Built {
        let span = lhs.expr.span.to(rhs.expr.span);
        let op_span = self.span(op);
        let Some(op) = binary_op(op.as_rule()) else {
            return self.placeholder(span);
        };
        let height = lhs.height.max(rhs.height);
        let kind = ExprKind::Binary {
            op,
            op_span,
            lhs: Box::new(lhs.expr),
            rhs: Box::new(rhs.expr),
        };
        self.node(kind, span, height)
    }

    /// Comparisons do not associate: `a < b < c` is an error, not `(a < b) < c`.
    fn comparison(&mut self, pair: Pair<Rule>) -> Built {
        let span = self.span(&pair);
        let mut parts = pair.into_inner();
        let Some(first) = parts.next() else {
            return self.placeholder(span);
        };
        let mut lhs = self.expr_node(first);
        // The previous comparison's operator, and whether its right side was a bare name.
        let mut previous: Option<(Rule, bool)> = None;
        while let (Some(op), Some(rhs)) = (parts.next(), parts.next()) {
            if let Some((previous_op, after_name)) = previous {
                // `map< f >(x)` reads as `map < f > (x)`.
                let spaced_functor =
                    previous_op == Rule::op_lt && op.as_rule() == Rule::op_gt && after_name;
                let help = if spaced_functor {
                    "a functor is written without spaces: `map<f>(…)`"
                } else {
                    "compare twice and join with `&&`: `a < b && b < c`"
                };
                let op_span = self.span(&op);
                self.diagnostics.push(
                    Diagnostic::error(SYNTAX, "comparison operators cannot be chained", op_span)
                        .with_primary_message("second comparison")
                        .with_help(help),
                );
            }
            let rhs = self.expr_node(rhs);
            previous = Some((op.as_rule(), matches!(rhs.expr.kind, ExprKind::Name(_))));
            lhs = self.binary(&op, lhs, rhs);
        }
        lhs
    }

    /// `-x`, `!x`, `- -x`: the operators apply right to left.
    fn prefix(&mut self, pair: Pair<Rule>) -> Built {
        let span = self.span(&pair);
        let mut parts: Vec<Pair<Rule>> = pair.into_inner().collect();
        let Some(operand) = parts.pop() else {
            return self.placeholder(span);
        };
        let mut built = self.expr_node(operand);
        while let Some(op) = parts.pop() {
            let op_span = self.span(&op);
            let op = if op.as_rule() == Rule::op_neg {
                UnaryOp::Neg
            } else {
                UnaryOp::Not
            };
            let span = op_span.to(built.expr.span);
            let kind = ExprKind::Unary {
                op,
                operand: Box::new(built.expr),
            };
            built = self.node(kind, span, built.height);
        }
        built
    }

    /// `a.b.c`: field accesses, left to right.
    fn postfix(&mut self, pair: Pair<Rule>) -> Built {
        let span = self.span(&pair);
        let mut parts = pair.into_inner();
        let Some(primary) = parts.next() else {
            return self.placeholder(span);
        };
        let mut built = self.expr_node(primary);
        for field in parts.filter_map(|field| field.into_inner().next()) {
            let field = self.ident(field);
            let span = built.expr.span.to(field.span);
            let kind = ExprKind::Field {
                base: Box::new(built.expr),
                field,
            };
            built = self.node(kind, span, built.height);
        }
        built
    }

    fn call(&mut self, pair: Pair<Rule>) -> Built {
        let span = self.span(&pair);
        let mut callee = None;
        let mut functor = None;
        let mut args = None;
        let mut height = 0;
        for part in pair.into_inner() {
            match part.as_rule() {
                Rule::ident => callee = Some(self.ident(part)),
                Rule::functor => functor = part.into_inner().next().map(|name| self.ident(name)),
                _ => {
                    let mut built_args = Vec::new();
                    for arg in part.into_inner() {
                        let mut arg_parts = arg.into_inner();
                        let (name, value) = match (arg_parts.next(), arg_parts.next()) {
                            (Some(name), Some(value)) => (Some(self.ident(name)), value),
                            (Some(value), None) => (None, value),
                            _ => continue,
                        };
                        let value = self.expr_node(value);
                        height = height.max(value.height);
                        built_args.push(Arg {
                            name,
                            value: value.expr,
                        });
                    }
                    args = Some(built_args);
                }
            }
        }
        let Some(callee) = callee else {
            return self.placeholder(span);
        };
        let call = Call {
            callee,
            functor,
            args,
            piped: None,
        };
        self.node(ExprKind::Call(call), span, height)
    }

    /// Integers must fit `i64`; floats need a fraction or an exponent and must be finite.
    fn number(&mut self, pair: Pair<Rule>) -> Built {
        let span = self.span(&pair);
        let text = pair.as_str();
        let kind = match classify_number(text) {
            NumberShape::Integer => match text.parse::<i64>() {
                Ok(value) => ExprKind::Int(value),
                Err(_) => {
                    self.diagnostics.push(
                        Diagnostic::error(
                            LITERAL,
                            format!(
                                "integer literal `{}` does not fit in 64 bits",
                                shortened(text)
                            ),
                            span,
                        )
                        .with_help(format!("the largest integer is {}", i64::MAX)),
                    );
                    ExprKind::Int(0)
                }
            },
            NumberShape::Float => match text.parse::<f64>() {
                Ok(value) if value.is_finite() => ExprKind::Float(value),
                _ => {
                    self.diagnostics.push(Diagnostic::error(
                        LITERAL,
                        format!("float literal `{}` is out of range", shortened(text)),
                        span,
                    ));
                    ExprKind::Float(0.0)
                }
            },
            NumberShape::Malformed => {
                self.diagnostics.push(
                    Diagnostic::error(
                        LITERAL,
                        format!("malformed number `{}`", shortened(text)),
                        span,
                    )
                    .with_help("numbers look like `4`, `0.05` or `1e-3`"),
                );
                ExprKind::Int(0)
            }
        };
        self.leaf(kind, span)
    }
}

enum NumberShape {
    Integer,
    Float,
    Malformed,
}

/// `digits`, or `digits[.digits][(e|E)[+|-]digits]` with a fraction or an exponent.
fn classify_number(text: &str) -> NumberShape {
    fn digits(s: &str) -> (&str, &str) {
        let end = s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
        s.split_at(end)
    }
    let (whole, rest) = digits(text);
    if whole.is_empty() {
        return NumberShape::Malformed;
    }
    if rest.is_empty() {
        return NumberShape::Integer;
    }
    let rest = match rest.strip_prefix('.') {
        Some(after_dot) => {
            let (fraction, after) = digits(after_dot);
            if fraction.is_empty() {
                return NumberShape::Malformed;
            }
            after
        }
        None => rest,
    };
    if rest.is_empty() {
        return NumberShape::Float;
    }
    let Some(exponent) = rest.strip_prefix(['e', 'E']) else {
        return NumberShape::Malformed;
    };
    let exponent = exponent.strip_prefix(['+', '-']).unwrap_or(exponent);
    match digits(exponent) {
        (power, "") if !power.is_empty() => NumberShape::Float,
        _ => NumberShape::Malformed,
    }
}

/// The children of a pair without keyword tokens, which carry no information.
fn significant(pair: Pair<Rule>) -> impl Iterator<Item = Pair<Rule>> {
    pair.into_inner().filter(|part| {
        !matches!(
            part.as_rule(),
            Rule::kw_use
                | Rule::kw_param
                | Rule::kw_fn
                | Rule::kw_pipeline
                | Rule::kw_out
                | Rule::kw_for
                | Rule::kw_in
                | Rule::kw_while
                | Rule::kw_if
                | Rule::kw_else
                | Rule::kw_break
                | Rule::kw_return
        )
    })
}

fn binary_op(rule: Rule) -> Option<BinaryOp> {
    let op = match rule {
        Rule::op_or => BinaryOp::Or,
        Rule::op_and => BinaryOp::And,
        Rule::op_eq => BinaryOp::Eq,
        Rule::op_ne => BinaryOp::Ne,
        Rule::op_lt => BinaryOp::Lt,
        Rule::op_le => BinaryOp::Le,
        Rule::op_gt => BinaryOp::Gt,
        Rule::op_ge => BinaryOp::Ge,
        Rule::op_add => BinaryOp::Add,
        Rule::op_sub => BinaryOp::Sub,
        Rule::op_mul => BinaryOp::Mul,
        Rule::op_div => BinaryOp::Div,
        Rule::op_rem => BinaryOp::Rem,
        _ => return None,
    };
    Some(op)
}
