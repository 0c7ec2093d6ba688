//! The spanned abstract syntax tree of a `.dpp` file, as the parser builds it.
//!
//! The AST is purely syntactic: names are not resolved, `use`s are not followed
//! and chains are kept as written (`Call::piped`), so diagnostics can point at
//! exactly what the user wrote.

use crate::source::{FileId, Span};

#[derive(Debug, Clone, PartialEq)]
pub struct Module {
    pub file: FileId,
    pub items: Vec<Item>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    Use(UseItem),
    Param(ParamItem),
    Fn(FnItem),
    Pipeline(PipelineItem),
}

/// `use "prelude.dpp"`; the path is relative to the file that holds the `use`.
#[derive(Debug, Clone, PartialEq)]
pub struct UseItem {
    pub path: String,
    pub path_span: Span,
    pub span: Span,
}

/// `param name = expr` (a host scalar, overridable with `--set name=value`).
#[derive(Debug, Clone, PartialEq)]
pub struct ParamItem {
    pub name: Ident,
    pub value: Expr,
    pub span: Span,
}

/// `fn name(a, b) { … return expr }`: a sub-pipeline, inlined at each call.
#[derive(Debug, Clone, PartialEq)]
pub struct FnItem {
    pub name: Ident,
    pub params: Vec<Ident>,
    pub body: Block,
    pub span: Span,
}

/// `pipeline name { … }`: the entry point of a file.
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineItem {
    pub name: Ident,
    pub body: Block,
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Block {
    pub stmts: Vec<Stmt>,
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Stmt {
    pub kind: StmtKind,
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub enum StmtKind {
    /// `x = expr` (one target) or `(x, y) = expr` (several).
    Bind {
        targets: Vec<Ident>,
        value: Expr,
    },
    /// `out name = expr`, or `out name` for an existing binding (`value` is `None`).
    Out {
        name: Ident,
        value: Option<Expr>,
    },
    /// `for var in start..end { body }` (end exclusive).
    For {
        var: Ident,
        start: Expr,
        end: Expr,
        body: Block,
    },
    While {
        cond: Expr,
        body: Block,
    },
    If {
        cond: Expr,
        then_block: Block,
        else_block: Option<Block>,
    },
    Break,
    Return(Expr),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Ident {
    pub name: String,
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    /// An integer literal (`4`).
    Int(i64),
    /// A literal with a decimal point or exponent (`0.05`, `1e-3`).
    Float(f64),
    Bool(bool),
    Name(Ident),
    /// `base.field`: a record field view (`rays.sample`) or a uniform (`camera.pixels`).
    Field {
        base: Box<Expr>,
        field: Ident,
    },
    /// A call: a primitive (`map<f>(…)`), a generator (`iota(n)`), a `fn`, a
    /// constructor (`vec3(0)`) or a host function (`len(a)`).
    Call(Call),
    Unary {
        op: UnaryOp,
        operand: Box<Expr>,
    },
    Binary {
        op: BinaryOp,
        /// The operator itself, where a type error between its operands points.
        op_span: Span,
        lhs: Box<Expr>,
        rhs: Box<Expr>,
    },
    /// `(a, b)`: several arrays as one multi-output value.
    Tuple(Vec<Expr>),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Call {
    pub callee: Ident,
    /// The functor between angle brackets: `map<intersect>`.
    pub functor: Option<Ident>,
    /// Positional and named arguments, in source order. `None` when the call
    /// has no parentheses (`→ map<occluded>`), which is only valid in a chain.
    pub args: Option<Vec<Arg>>,
    /// `a → call(…)`: the left-hand side of the arrow, passed as the leading
    /// array argument(s). Chains nest to the left: `a → f → g` is `g { piped: f { piped: a } }`.
    pub piped: Option<Box<Expr>>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Arg {
    /// `Some` for `key: value` (a uniform argument).
    pub name: Option<Ident>,
    pub value: Expr,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnaryOp {
    Neg,
    Not,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinaryOp {
    Add,
    Sub,
    Mul,
    Div,
    Rem,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    And,
    Or,
}

impl BinaryOp {
    pub fn symbol(self) -> &'static str {
        match self {
            BinaryOp::Add => "+",
            BinaryOp::Sub => "-",
            BinaryOp::Mul => "*",
            BinaryOp::Div => "/",
            BinaryOp::Rem => "%",
            BinaryOp::Eq => "==",
            BinaryOp::Ne => "!=",
            BinaryOp::Lt => "<",
            BinaryOp::Le => "<=",
            BinaryOp::Gt => ">",
            BinaryOp::Ge => ">=",
            BinaryOp::And => "&&",
            BinaryOp::Or => "||",
        }
    }
}
