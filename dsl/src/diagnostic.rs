//! Diagnostics: one message, spanned labels and an optional help line.
//! Both the parser and the plan compiler report through this type.

use crate::source::Span;

/// Every diagnostic code of the language, in one table: the stable,
/// greppable names users see (`dpp::syntax`), from the parser's and the plan
/// compiler's passes alike. docs/language.md §5 lists them with examples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Code {
    /// `dpp::syntax`: the text does not follow the grammar.
    Syntax,
    /// `dpp::literal`: a number literal out of range or malformed.
    Literal,
    /// `dpp::nesting`: expressions or blocks nested deeper than the parser allows.
    Nesting,
    /// `dpp::io`: a pipeline file that cannot be read.
    Io,
    /// `dpp::use-missing`: a `use` of a file that does not exist.
    UseMissing,
    /// `dpp::use-cycle`: files that `use` each other in a circle.
    UseCycle,
    /// `dpp::duplicate`: a name defined twice.
    Duplicate,
    /// `dpp::reserved`: a definition that takes the name of a primitive or built-in.
    Reserved,
    /// `dpp::no-pipeline`: a file without a pipeline.
    NoPipeline,
    /// `dpp::param`: a `param` whose value is not a constant.
    Param,
    /// `dpp::set`: a `--set` that names no param or gives a value of the wrong type.
    Set,
    /// `dpp::param-rebind`: a statement that rebinds a param.
    ParamRebind,
    /// `dpp::return`: a misplaced or missing `return` in a `fn`.
    Return,
    /// `dpp::recursion`: a `fn` that calls itself, directly or not.
    Recursion,
    /// `dpp::while-condition`: a `while` condition that is not a host boolean.
    WhileCondition,
    /// `dpp::break-outside-loop`: `break` outside a loop.
    BreakOutsideLoop,
    /// `dpp::arity`: a call with the wrong number of arguments.
    Arity,
    /// `dpp::unknown-name`: a name that is not defined.
    UnknownName,
    /// `dpp::unknown-functor`: a functor the library does not have.
    UnknownFunctor,
    /// `dpp::unknown-argument`: a named argument the callee does not take.
    UnknownArgument,
    /// `dpp::missing-argument`: a required named argument left out.
    MissingArgument,
    /// `dpp::missing-functor`: a primitive that needs a functor without one.
    MissingFunctor,
    /// `dpp::functor-kind`: a functor of a kind the primitive cannot apply.
    FunctorKind,
    /// `dpp::functor-on-non-primitive`: angle brackets on a callee that is not a primitive.
    FunctorOnNonPrimitive,
    /// `dpp::scatter-target`: a `scatter` without exactly one of `len:` and `into:`.
    ScatterTarget,
    /// `dpp::expected-array`: a host scalar where an array is needed.
    ExpectedArray,
    /// `dpp::expected-scalar`: an array where a host scalar is needed.
    ExpectedScalar,
    /// `dpp::type-mismatch`: a value of the wrong type.
    TypeMismatch,
    /// `dpp::length-mismatch`: arrays whose lengths are known to differ.
    LengthMismatch,
    /// `dpp::unknown-field`: a record or uniform field that does not exist.
    UnknownField,
    /// `dpp::uniform`: a uniform the library does not provide.
    Uniform,
    /// `dpp::composite`: a `composite` that is misplaced, or whose blend does not fit it.
    Composite,
    /// `dpp::internal`: a compiler bug: the plan broke an invariant after a pass.
    Internal,
}

impl Code {
    /// The code as printed: `dpp::unknown-name`.
    pub fn as_str(self) -> &'static str {
        match self {
            Code::Syntax => "dpp::syntax",
            Code::Literal => "dpp::literal",
            Code::Nesting => "dpp::nesting",
            Code::Io => "dpp::io",
            Code::UseMissing => "dpp::use-missing",
            Code::UseCycle => "dpp::use-cycle",
            Code::Duplicate => "dpp::duplicate",
            Code::Reserved => "dpp::reserved",
            Code::NoPipeline => "dpp::no-pipeline",
            Code::Param => "dpp::param",
            Code::Set => "dpp::set",
            Code::ParamRebind => "dpp::param-rebind",
            Code::Return => "dpp::return",
            Code::Recursion => "dpp::recursion",
            Code::WhileCondition => "dpp::while-condition",
            Code::BreakOutsideLoop => "dpp::break-outside-loop",
            Code::Arity => "dpp::arity",
            Code::UnknownName => "dpp::unknown-name",
            Code::UnknownFunctor => "dpp::unknown-functor",
            Code::UnknownArgument => "dpp::unknown-argument",
            Code::MissingArgument => "dpp::missing-argument",
            Code::MissingFunctor => "dpp::missing-functor",
            Code::FunctorKind => "dpp::functor-kind",
            Code::FunctorOnNonPrimitive => "dpp::functor-on-non-primitive",
            Code::ScatterTarget => "dpp::scatter-target",
            Code::ExpectedArray => "dpp::expected-array",
            Code::ExpectedScalar => "dpp::expected-scalar",
            Code::TypeMismatch => "dpp::type-mismatch",
            Code::LengthMismatch => "dpp::length-mismatch",
            Code::UnknownField => "dpp::unknown-field",
            Code::Uniform => "dpp::uniform",
            Code::Composite => "dpp::composite",
            Code::Internal => "dpp::internal",
        }
    }
}

impl std::fmt::Display for Code {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Label {
    pub span: Span,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    /// What kind of mistake it is (printed as `dpp::syntax`, `dpp::unknown-name`).
    pub code: Code,
    /// One line saying what is wrong.
    pub message: String,
    /// The first label is the primary one; it decides the reported line and column.
    pub labels: Vec<Label>,
    /// A hint such as "did you mean `intersect`?".
    pub help: Option<String>,
}

impl Diagnostic {
    pub fn error(code: Code, message: impl Into<String>, span: Span) -> Diagnostic {
        Diagnostic {
            code,
            message: message.into(),
            labels: vec![Label {
                span,
                message: String::new(),
            }],
            help: None,
        }
    }

    pub fn with_label(mut self, span: Span, message: impl Into<String>) -> Diagnostic {
        self.labels.push(Label {
            span,
            message: message.into(),
        });
        self
    }

    /// Sets the message of the primary label.
    pub fn with_primary_message(mut self, message: impl Into<String>) -> Diagnostic {
        if let Some(first) = self.labels.first_mut() {
            first.message = message.into();
        }
        self
    }

    pub fn with_help(mut self, help: impl Into<String>) -> Diagnostic {
        self.help = Some(help.into());
        self
    }
}
