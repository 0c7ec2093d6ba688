//! Valid `.dpp` snippets and the AST they parse to, as insta snapshots.
//!
//! The AST is printed as S-expressions (spans would drown `Debug` output);
//! the `spans_*` cases print every node with its span and source text instead.

use std::fmt::Write as _;

use dpp_dsl::ast::{Block, Call, Expr, ExprKind, Ident, Item, Module, Stmt, StmtKind, UnaryOp};
use dpp_dsl::{parse_module, render, FileId, SourceMap, Span};

const WORKLOAD3: &str = include_str!("../data/workload3.dpp");
const PRELUDE: &str = include_str!("../data/prelude.dpp");

/// Parses `source`, which must be valid, and snapshots it with its S-expression form.
fn check(name: &str, source: &str) {
    let module = parse(source);
    let snapshot = format!("{source}\n---\n{}", SexprPrinter::module(&module));
    insta::assert_snapshot!(name, snapshot);
}

/// Like [`check`], but the snapshot lists every node with its span.
fn check_spans(name: &str, source: &str) {
    let module = parse(source);
    let mut printer = SpanPrinter {
        source,
        out: String::new(),
        depth: 0,
    };
    printer.module(&module);
    insta::assert_snapshot!(name, format!("{source}\n---\n{}", printer.out));
}

fn parse(source: &str) -> Module {
    match parse_module(FileId(0), source) {
        Ok(module) => module,
        Err(diagnostics) => {
            let mut sources = SourceMap::default();
            sources.add("test.dpp", source);
            panic!(
                "expected a valid snippet:\n{}",
                render(&diagnostics, &sources, false)
            );
        }
    }
}

macro_rules! cases {
    ($check:ident: $($name:ident => $source:expr,)*) => {
        $(
            #[test]
            fn $name() {
                $check(stringify!($name), $source);
            }
        )*
    };
}

cases! { check:
    spec_workload3 => WORKLOAD3,
    spec_prelude => PRELUDE,
    empty_file => "",
    only_comments => "// nothing here\n   // still nothing\n",
    items => "use \"lib/prelude.dpp\"\nparam a = 1\nparam b = 2.5\nparam c = false\nfn id(x) { return x }\nfn pair(a, b,) { return a }\nfn none() { return 0 }\npipeline main { out x = 1 }",
    items_on_one_line => "param a = 1 param b = 2 pipeline p { out a }",
    literals => "pipeline p {\n a = 0\n b = 42\n c = 0.05\n d = 1e-3\n e = 2.5E+2\n f = 9223372036854775807\n g = true\n h = false\n}",
    arrow_chains => "pipeline p {\n a = x → map<f>\n b = x -> map<f> -> gather<g>(group: 4)\n c = x→map<f>(y)→reduce<add>\n d = f(a → map<g>)\n}",
    chain_continues_on_next_line => "pipeline p {\n occlusion = scatter<occRayGen>(surf, fanout: k)\n     → map<occluded>\n     -> gather<average>(group: k)\n}",
    chain_is_loosest => "pipeline p { a = n * 2 + 1 → map<f> }",
    calls => "pipeline p {\n a = iota(n)\n b = f()\n c = map<f>(a, b, key: c, other: 1 + 2,)\n d = map<f>\n e = map<f> (a)\n}",
    tuple_bindings => "pipeline p {\n (x, y) = map<f>(a)\n (only) = g(a)\n (a, b, c,) = h(a)\n}",
    tuple_binding_after_name_on_previous_line => "pipeline p {\n a = b\n (x, y) = c\n d = e // comment\n (z, w) = f\n}",
    out_forms => "pipeline p {\n out image = gather<antiAlias>(color, group: spp)\n out depth\n x = 1\n}",
    semicolons => "pipeline p { a = 1; b = 2;; c = a + b; out c; }",
    control_flow => "fn f(n) {\n for i in 0..n { x = i }\n for j in a.b..len(c) - 1 { break }\n while n > 0 && !done { n = n - 1 }\n return n\n}",
    if_else => "pipeline p {\n if a { x = 1 }\n if b { x = 2 } else { x = 3 }\n if c { break }\n}",
    else_if_chain => "pipeline p {\n if a { x = 1 } else if b { x = 2 } else if c { x = 3 } else { x = 4 }\n if d { y = 1 } else if e { y = 2 }\n}",
    precedence => "pipeline p {\n a = 1 + 2 * 3 - 4 / 5 % 6\n b = -x * -y\n c = !a || b && c == d\n d = a < b || c >= d && e != f\n e = (1 + 2) * 3\n f = - - x\n g = a - -b\n h = a-b\n i = a <= b\n j = x.y * 2\n}",
    field_chains => "pipeline p {\n a = camera.pixels\n b = scene.lights.count\n c = f(x).y.z\n d = (a).b\n}",
    comparison_is_not_a_functor => "pipeline p {\n if i<n { x = 1 }\n if a<b && c>d { x = 2 }\n y = a < b\n}",
    keywords_inside_names => "param input = 1\nparam format = 2\npipeline outIn { iffy = input + format; returned = 1; breakfast = fnord; truely = true }",
    unicode_in_comments => "// résumé → ∑\npipeline p { out x = 1 } // ünïcode",
    comments_between_tokens => "pipeline p {\n x = a // the source\n   // a whole comment line\n   → map<f> // then f\n   -> gather<g>(group: 2, // per pair\n   )\n}",
    tuples => "fn two(a, b) { return (b, a,) }\npipeline p {\n (x, y) = (a, map<f>(b))\n z = (a, b) → map<g>\n w = (a)\n}",
    crlf_and_tabs => "param a = 1\r\n\r\npipeline p {\r\n\tx = a -> map<f>\r\n\t(y, z) = x\t// c\r\n\tout y\r\n}\r\n",
}

cases! { check_spans:
    spans_workload3_excerpt => "pipeline w {\n    rays = iota(camera.pixels * spp) → map<cameraRay>(spp: spp)\n    (a, b) = map<f>(rays) -> map<g>\n    out image\n}",
    spans_else_if => "fn f(a) {\n  if a { return 1 } else if b { return 2 } else { return 3 }\n}",
    spans_use_param => "use \"x.dpp\" // tail\nparam p = -(1 + 2)",
}

// ---- printers -----------------------------------------------------------------

/// A compact S-expression form of the AST: `(= x (+ 1 2))`.
struct SexprPrinter;

impl SexprPrinter {
    fn module(module: &Module) -> String {
        let mut out = String::new();
        for item in &module.items {
            match item {
                Item::Use(item) => writeln!(out, "(use {:?})", item.path),
                Item::Param(item) => writeln!(
                    out,
                    "(param {} {})",
                    item.name.name,
                    Self::expr(&item.value)
                ),
                Item::Fn(item) => {
                    let params: Vec<&str> = item.params.iter().map(|p| p.name.as_str()).collect();
                    writeln!(
                        out,
                        "(fn {} ({}){})",
                        item.name.name,
                        params.join(" "),
                        Self::block(&item.body, 1)
                    )
                }
                Item::Pipeline(item) => {
                    writeln!(
                        out,
                        "(pipeline {}{})",
                        item.name.name,
                        Self::block(&item.body, 1)
                    )
                }
            }
            .unwrap();
        }
        out
    }

    /// Statements on their own lines, indented by `depth`.
    fn block(block: &Block, depth: usize) -> String {
        block
            .stmts
            .iter()
            .map(|stmt| format!("\n{}{}", "  ".repeat(depth), Self::stmt(stmt, depth)))
            .collect()
    }

    fn stmt(stmt: &Stmt, depth: usize) -> String {
        let indent = "  ".repeat(depth);
        match &stmt.kind {
            StmtKind::Bind { targets, value } => {
                let targets: Vec<&str> = targets.iter().map(|t| t.name.as_str()).collect();
                let targets = if targets.len() == 1 {
                    targets[0].to_string()
                } else {
                    format!("({})", targets.join(" "))
                };
                format!("(= {targets} {})", Self::expr(value))
            }
            StmtKind::Out {
                name,
                value: Some(value),
            } => format!("(out {} {})", name.name, Self::expr(value)),
            StmtKind::Out { name, value: None } => format!("(out {})", name.name),
            StmtKind::For {
                var,
                start,
                end,
                body,
            } => format!(
                "(for {} {} {}{})",
                var.name,
                Self::expr(start),
                Self::expr(end),
                Self::block(body, depth + 1)
            ),
            StmtKind::While { cond, body } => format!(
                "(while {}{})",
                Self::expr(cond),
                Self::block(body, depth + 1)
            ),
            StmtKind::If {
                cond,
                then_block,
                else_block,
            } => {
                let mut out = format!(
                    "(if {}{}",
                    Self::expr(cond),
                    Self::block(then_block, depth + 1)
                );
                if let Some(else_block) = else_block {
                    write!(out, "\n{indent} else{}", Self::block(else_block, depth + 1)).unwrap();
                }
                out + ")"
            }
            StmtKind::Break => "(break)".into(),
            StmtKind::Return(value) => format!("(return {})", Self::expr(value)),
        }
    }

    fn expr(expr: &Expr) -> String {
        match &expr.kind {
            ExprKind::Int(value) => value.to_string(),
            ExprKind::Float(value) => format!("{value:?}"),
            ExprKind::Bool(value) => value.to_string(),
            ExprKind::Name(name) => name.name.clone(),
            ExprKind::Field { base, field } => format!("(. {} {})", Self::expr(base), field.name),
            ExprKind::Call(call) => Self::call(call),
            ExprKind::Unary { op, operand } => {
                let op = match op {
                    UnaryOp::Neg => "neg",
                    UnaryOp::Not => "!",
                };
                format!("({op} {})", Self::expr(operand))
            }
            ExprKind::Binary { op, lhs, rhs, .. } => {
                format!("({} {} {})", op.symbol(), Self::expr(lhs), Self::expr(rhs))
            }
            ExprKind::Tuple(elements) => {
                let elements: Vec<String> = elements.iter().map(Self::expr).collect();
                format!("(tuple {})", elements.join(" "))
            }
        }
    }

    /// `(call map<f> (piped x) (args a (key: b)))`; no `(args …)` when the call has no parentheses.
    fn call(call: &Call) -> String {
        let mut out = format!("(call {}", call.callee.name);
        if let Some(functor) = &call.functor {
            write!(out, "<{}>", functor.name).unwrap();
        }
        if let Some(piped) = &call.piped {
            write!(out, " (piped {})", Self::expr(piped)).unwrap();
        }
        if let Some(args) = &call.args {
            out.push_str(" (args");
            for arg in args {
                match &arg.name {
                    Some(name) => write!(out, " ({}: {})", name.name, Self::expr(&arg.value)),
                    None => write!(out, " {}", Self::expr(&arg.value)),
                }
                .unwrap();
            }
            out.push(')');
        }
        out + ")"
    }
}

/// One line per node: its kind, byte span and the source text it covers.
struct SpanPrinter<'s> {
    source: &'s str,
    out: String,
    depth: usize,
}

impl SpanPrinter<'_> {
    fn line(&mut self, what: &str, span: Span) {
        let text = &self.source[span.start..span.end];
        writeln!(
            self.out,
            "{}{what} {}..{} «{text}»",
            "  ".repeat(self.depth),
            span.start,
            span.end
        )
        .unwrap();
    }

    fn nested(&mut self, what: &str, span: Span, children: impl FnOnce(&mut Self)) {
        self.line(what, span);
        self.depth += 1;
        children(self);
        self.depth -= 1;
    }

    fn ident(&mut self, what: &str, ident: &Ident) {
        self.line(what, ident.span);
    }

    fn module(&mut self, module: &Module) {
        for item in &module.items {
            match item {
                Item::Use(item) => {
                    self.nested("use", item.span, |p| p.line("path", item.path_span))
                }
                Item::Param(item) => self.nested("param", item.span, |p| {
                    p.ident("name", &item.name);
                    p.expr(&item.value);
                }),
                Item::Fn(item) => self.nested("fn", item.span, |p| {
                    p.ident("name", &item.name);
                    item.params.iter().for_each(|param| p.ident("param", param));
                    p.block(&item.body);
                }),
                Item::Pipeline(item) => self.nested("pipeline", item.span, |p| {
                    p.ident("name", &item.name);
                    p.block(&item.body);
                }),
            }
        }
    }

    fn block(&mut self, block: &Block) {
        self.nested("block", block.span, |p| {
            block.stmts.iter().for_each(|stmt| p.stmt(stmt))
        });
    }

    fn stmt(&mut self, stmt: &Stmt) {
        match &stmt.kind {
            StmtKind::Bind { targets, value } => self.nested("bind", stmt.span, |p| {
                targets.iter().for_each(|target| p.ident("target", target));
                p.expr(value);
            }),
            StmtKind::Out { name, value } => self.nested("out", stmt.span, |p| {
                p.ident("name", name);
                value.iter().for_each(|value| p.expr(value));
            }),
            StmtKind::For {
                var,
                start,
                end,
                body,
            } => self.nested("for", stmt.span, |p| {
                p.ident("var", var);
                p.expr(start);
                p.expr(end);
                p.block(body);
            }),
            StmtKind::While { cond, body } => self.nested("while", stmt.span, |p| {
                p.expr(cond);
                p.block(body);
            }),
            StmtKind::If {
                cond,
                then_block,
                else_block,
            } => self.nested("if", stmt.span, |p| {
                p.expr(cond);
                p.block(then_block);
                else_block.iter().for_each(|block| p.block(block));
            }),
            StmtKind::Break => self.line("break", stmt.span),
            StmtKind::Return(value) => self.nested("return", stmt.span, |p| p.expr(value)),
        }
    }

    fn expr(&mut self, expr: &Expr) {
        match &expr.kind {
            ExprKind::Int(_) => self.line("int", expr.span),
            ExprKind::Float(_) => self.line("float", expr.span),
            ExprKind::Bool(_) => self.line("bool", expr.span),
            ExprKind::Name(name) => self.nested("name", expr.span, |p| p.ident("ident", name)),
            ExprKind::Field { base, field } => self.nested("field", expr.span, |p| {
                p.expr(base);
                p.ident("field", field);
            }),
            ExprKind::Call(call) => self.nested("call", expr.span, |p| {
                p.ident("callee", &call.callee);
                call.functor
                    .iter()
                    .for_each(|functor| p.ident("functor", functor));
                call.piped.iter().for_each(|piped| p.expr(piped));
                for arg in call.args.iter().flatten() {
                    arg.name.iter().for_each(|name| p.ident("arg name", name));
                    p.expr(&arg.value);
                }
            }),
            ExprKind::Unary { operand, .. } => self.nested("unary", expr.span, |p| p.expr(operand)),
            ExprKind::Binary { lhs, rhs, .. } => self.nested("binary", expr.span, |p| {
                p.expr(lhs);
                p.expr(rhs);
            }),
            ExprKind::Tuple(elements) => self.nested("tuple", expr.span, |p| {
                elements.iter().for_each(|e| p.expr(e));
            }),
        }
    }
}
