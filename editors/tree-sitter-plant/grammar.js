/**
 * Tree-sitter grammar of plantc model files (`.plant`).
 *
 * The language reference is the doc comment of `derive/src/lang/mod.rs`.
 * Statements end at the end of their line in the real parser; here line ends
 * are whitespace, which gives the same tree for every valid file because a
 * statement always starts with a keyword (or, in a controller, `name =`) and
 * two expressions are never written side by side. The grammar is for
 * highlighting and editor navigation; `plantc check` is the authority.
 */

/// @ts-check

const PREC = {
  or: 1,
  and: 2,
  additive: 1,
  multiplicative: 2,
  unary: 3,
  power: 4,
};

function commaSep(rule) {
  return optional(seq(rule, repeat(seq(',', rule)), optional(',')));
}

module.exports = grammar({
  name: 'plant',

  extras: $ => [/[ \t\r\n]/, $.comment],

  word: $ => $.identifier,

  rules: {
    source_file: $ => repeat($._statement),

    _statement: $ => choice(
      $.model_declaration,
      $.coordinate_declaration,
      $.input_declaration,
      $.output_declaration,
      $.parameter_declaration,
      $.let_declaration,
      $.energy_declaration,
      $.force_declaration,
      $.signal_effect_declaration,
      $.set_block,
      $.controller_block,
      $.recorded_controller_block,
    ),

    model_declaration: $ => seq('model', field('name', $.identifier), optional(field('title', $.string))),

    coordinate_declaration: $ => seq(
      'coordinate',
      field('name', $.identifier),
      ':',
      field('kind', $.coordinate_kind),
      optional(field('doc', $.string)),
    ),

    coordinate_kind: _ => choice('angle', 'length'),

    input_declaration: $ => seq(
      'input',
      field('name', $.identifier),
      optional(field('unit', $.unit)),
      repeat(choice($.limits, field('doc', $.string))),
    ),

    limits: $ => seq('limits', $.bounds),

    output_declaration: $ => seq(
      'output',
      field('name', $.identifier),
      optional(seq('=', field('value', $._expression))),
      optional(field('doc', $.string)),
    ),

    parameter_declaration: $ => seq(
      'parameter',
      field('name', $.identifier),
      '=',
      field('value', $.signed_number),
      optional(field('unit', $.unit)),
      repeat(choice($.estimate, field('doc', $.string))),
    ),

    estimate: $ => seq('estimate', $.bounds),

    bounds: $ => seq('[', $.signed_number, ',', $.signed_number, ']'),

    let_declaration: $ => seq('let', field('name', $.identifier), '=', field('value', $._expression)),

    energy_declaration: $ => seq(
      choice('kinetic', 'potential'),
      field('name', $.identifier),
      '=',
      field('value', $._expression),
    ),

    force_declaration: $ => seq(
      'force',
      field('coordinate', $.identifier),
      '=',
      field('value', $._expression),
    ),

    // `sensor q = ...`, `actuator u = ...`, `inertia q = ...`: one effect call each
    signal_effect_declaration: $ => seq(
      choice('sensor', 'actuator', 'inertia'),
      field('target', $.identifier),
      '=',
      field('value', $._expression),
    ),

    set_block: $ => seq(
      'set',
      field('name', $.identifier),
      optional(field('title', $.string)),
      '{',
      repeat($.set_entry),
      '}',
    ),

    set_entry: $ => seq(field('name', $.identifier), '=', field('value', $._expression)),

    controller_block: $ => seq(
      'controller',
      field('name', $.identifier),
      optional(field('title', $.string)),
      '{',
      repeat($._controller_statement),
      '}',
    ),

    _controller_statement: $ => choice(
      $.place_statement,
      $.lqr_statement,
      $.gains_statement,
      $.linearize_statement,
      $.gain_statement,
      $.surface_statement,
      $.mode_statement,
      $.switch_statement,
      $.wrap_statement,
      $.law_statement,
    ),

    // `surface s poles [...]` or `surface s = expr` (sliding mode)
    surface_statement: $ => seq(
      'surface',
      field('name', $.identifier),
      choice(
        seq('poles', '[', commaSep($.pole), ']'),
        seq('=', field('value', $._expression)),
      ),
    ),

    // `mode name = controller [swing_up]` (hybrid controllers)
    mode_statement: $ => seq(
      'mode',
      field('name', $.identifier),
      '=',
      field('controller', $.identifier),
      optional('swing_up'),
    ),

    // `switch a -> b when condition`
    switch_statement: $ => seq(
      'switch',
      field('from', $.identifier),
      '->',
      field('to', $.identifier),
      'when',
      field('condition', $._condition),
    ),

    // `wrap q`: the modes and conditions see angle q wrapped into [-pi, pi)
    wrap_statement: $ => seq('wrap', field('coordinate', $.identifier)),

    _condition: $ => choice($.comparison, $.condition),

    condition: $ => choice(
      prec.left(PREC.or, seq(field('left', $._condition), field('operator', 'or'), field('right', $._condition))),
      prec.left(PREC.and, seq(field('left', $._condition), field('operator', 'and'), field('right', $._condition))),
    ),

    comparison: $ => seq(
      field('left', $._expression),
      field('operator', choice('<', '<=', '>', '>=')),
      field('right', $._expression),
    ),

    // `recorded controller name "title" { ... }`: the law that made a
    // recording's input, replayed by identification
    recorded_controller_block: $ => seq(
      'recorded',
      'controller',
      field('name', $.identifier),
      optional(field('title', $.string)),
      '{',
      repeat($._recorded_statement),
      '}',
    ),

    _recorded_statement: $ => choice(
      $.signal_statement,
      $.gain_statement,
      $.let_declaration,
      $.law_statement,
    ),

    // `signal name [unit] "doc"`: a data column the law reads
    signal_statement: $ => seq(
      'signal',
      field('name', $.identifier),
      optional(field('unit', $.unit)),
      optional(field('doc', $.string)),
    ),

    place_statement: $ => seq('place', 'poles', '[', commaSep($.pole), ']'),

    pole: $ => seq(
      optional(choice('-', '+')),
      choice(
        seq($.number, optional(seq(choice('+', '-'), $.imaginary))),
        $.imaginary,
      ),
    ),

    lqr_statement: $ => seq('lqr', 'Q', $.number_list, 'R', $.number_list),

    gains_statement: $ => seq('gains', field('name', $.identifier), $.number_list),

    number_list: $ => seq('[', commaSep($.signed_number), ']'),

    linearize_statement: $ => seq('linearize', 'output', field('output', $.identifier)),

    gain_statement: $ => seq('gain', field('name', $.identifier), '=', field('value', $._expression)),

    law_statement: $ => seq(field('target', $.identifier), '=', field('value', $._expression)),

    // ---- expressions ----

    _expression: $ => choice(
      $.binary_expression,
      $.unary_expression,
      $.call,
      $.derivative,
      $.identifier,
      $.number,
      $.quantity,
      $.parenthesized_expression,
    ),

    binary_expression: $ => choice(
      prec.left(PREC.additive, seq(field('left', $._expression), field('operator', choice('+', '-')), field('right', $._expression))),
      prec.left(PREC.multiplicative, seq(field('left', $._expression), field('operator', choice('*', '/')), field('right', $._expression))),
      prec.right(PREC.power, seq(field('left', $._expression), field('operator', '^'), field('right', $._expression))),
    ),

    unary_expression: $ => prec(PREC.unary, seq(field('operator', choice('-', '+')), field('operand', $._expression))),

    call: $ => seq(
      field('function', $.identifier),
      '(',
      field('arguments', optional(seq($._expression, repeat(seq(',', $._expression))))),
      ')',
    ),

    derivative: $ => seq(field('name', $.identifier), field('order', alias(token.immediate(/''?/), $.prime))),

    quantity: $ => seq($.number, $.unit),

    parenthesized_expression: $ => seq('(', $._expression, ')'),

    signed_number: $ => seq(optional(choice('-', '+')), $.number),

    // ---- units ----

    unit: $ => seq('[', repeat(choice(alias($.identifier, $.unit_name), $.number, '*', '/', '^', '-', '(', ')')), ']'),

    // ---- tokens ----

    identifier: _ => /[A-Za-z_][A-Za-z0-9_]*/,

    number: _ => /(\d+(\.\d+)?|\.\d+)([eE][+-]?\d+)?/,

    imaginary: _ => /(\d+(\.\d+)?|\.\d+)([eE][+-]?\d+)?i/,

    string: _ => /"([^"\\\n]|\\.)*"/,

    comment: _ => token(seq('#', /.*/)),
  },
});
