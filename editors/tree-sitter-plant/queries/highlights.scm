; Highlighting of plantc model files (Neovim, Helix, tree-sitter highlight).

(comment) @comment
(string) @string
[(number) (imaginary)] @number

[
  "model" "coordinate" "input" "output" "parameter" "let" "kinetic"
  "potential" "force" "sensor" "actuator" "inertia" "set" "controller" "recorded"
] @keyword

["limits" "estimate" "place" "poles" "lqr" "Q" "R" "gains" "linearize" "gain"
 "surface" "mode" "switch" "wrap" "when" "swing_up" "signal"] @keyword

["and" "or"] @keyword.operator

(coordinate_kind) @type.builtin
(unit "[" @punctuation.special "]" @punctuation.special)
(unit_name) @type

(model_declaration name: (identifier) @namespace)
(set_block name: (identifier) @namespace)
(controller_block name: (identifier) @namespace)
(recorded_controller_block name: (identifier) @namespace)
(mode_statement controller: (identifier) @namespace)

(coordinate_declaration name: (identifier) @variable.parameter)
(input_declaration name: (identifier) @variable.parameter)
(parameter_declaration name: (identifier) @constant)
(set_entry name: (identifier) @constant)
(let_declaration name: (identifier) @variable)
(energy_declaration name: (identifier) @variable)
(output_declaration name: (identifier) @variable)
(force_declaration coordinate: (identifier) @variable.parameter)
(signal_effect_declaration target: (identifier) @variable.parameter)
(gain_statement name: (identifier) @constant)
(gains_statement name: (identifier) @constant)
(law_statement target: (identifier) @variable)
(surface_statement name: (identifier) @variable)
(mode_statement name: (identifier) @label)
(switch_statement from: (identifier) @label)
(switch_statement to: (identifier) @label)
(wrap_statement coordinate: (identifier) @variable.parameter)
(signal_statement name: (identifier) @variable.parameter)
(derivative name: (identifier) @variable.parameter)
(derivative order: (prime) @operator)

((call function: (identifier) @function.builtin)
  (#match? @function.builtin "^(sin|cos|tan|sqrt|exp|ln|abs|sign|tanh|atan2|sat|energy|derivative)$"))
((call function: (identifier) @function.macro)
  (#match? @function.macro "^(viscous_friction|coulomb_friction|stribeck_friction|quadratic_drag|spring|cogging|speed_limit|sensor_offset|input_offset|input_delay|deadzone|saturation|added_inertia)$"))
(call function: (identifier) @function)

((identifier) @constant.builtin
  (#eq? @constant.builtin "pi"))

["+" "-" "*" "/" "^" "=" ":" "<" "<=" ">" ">=" "->"] @operator
["(" ")" "[" "]" "{" "}"] @punctuation.bracket
"," @punctuation.delimiter
