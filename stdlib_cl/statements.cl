// The statements the emitter writes from a scene's IR (fractalc/emit.py,
// `_FunctionWriter`): each template one statement or a block's line, which
// the emitter indents to its depth; `$value`s are the IR's C expressions
// (the op table's, fractalc/ir.py) and names the emitter makes. A `//@ NAME`
// line opens the template NAME (fractalc/stdlib.py `templates`).

//@ function  a function of the point: `$body` its statements, each line ending in a newline
$signature {
${body}    return $result;
}

//@ function_of_points  a function of several points: `$body` its statements, the last storing the results
$signature {
${body}}

//@ declare  a value computed once and named
$type $name = $value;

//@ declare_unset  a value a uniform branch sets on both of its sides
$type $name;

//@ assign
$name = $value;

//@ store_result  a function of several points' result at one
*$name = $value;

//@ assign_selected  a per-ray value, changed only for the rays of `mask`
$name = SELECT($name, $value, $mask);

//@ loop  a loop's head: its body and `end` follow
for (int $counter = 0; $counter < $count; $counter++) {

//@ narrow  rays whose loop condition fails stop
$active = $active & $condition;

//@ loop_stop  the loop ends when none of its rays is left
if (!ANY($active)) break;

//@ count_iterations  the counting build's hook (stdlib_cl/count.cl): one iteration of the rays of `rays`
COUNT_ITERATIONS($rays);

//@ if_any  a per-ray branch's head: its side is computed where some ray needs it
if (ANY($condition)) {

//@ if  a uniform branch's head
if ($condition) {

//@ else
} else {

//@ end  a block's end
}
