// Templates of the functions the emitter writes from a scene's IR
// (fractalc/emit.py) around the statements computing it: `$body` is those
// statements, each line ending in a newline. A `//@ NAME` line opens the
// template NAME (fractalc/stdlib.py `templates`).

//@ surface_at  the surface properties at a point: the nearest part's material
typedef struct { real $fields; } surface;

surface surface_at(vec3 p, __constant scalar *params) {
${body}    surface s = { $values };
    return s;
}

//@ scene_bound  the radius and (through `centre`) the centre of a sphere holding the scene but its ground half-spaces
real scene_bound(__constant scalar *params, vec3 *centre) {
${body}    *centre = v3($x, $y, $z);
    return $radius;
}

//@ clear_of_half_spaces  `$tests`: a half_space_test per ground half-space
// Whether rays from `origin` along `dir` stay clear of every ground half-space
// n.p <= offset: they start above it (by `height`) and move away from it.
mask clear_of_half_spaces(vec3 origin, vec3 dir, real height, __constant scalar *params) {
${body}    mask clear = MASK_TRUE;
${tests}    return clear;
}

//@ half_space_test
    {   vec3 n = v3($normal);
        clear = clear & (v3_dot(origin, n) - $offset >= height) & (v3_dot(dir, n) >= 0.0f);   }

//@ normals  `estimate_normal` at any point, and `estimate_hit_normal` where a march hit with the estimate `here`
vec3 estimate_normal(vec3 p, real h, __constant scalar *params) {
    return $anywhere;
}

vec3 estimate_hit_normal(vec3 p, real here, real h, __constant scalar *params) {
    return $at_hit;
}

//@ normal  a normal by the method's own evaluations
${method}_normal(p, h, params)

//@ forward_normal_anywhere  forward differences from the estimate at the point
forward_normal(p, distance_estimate(p, params), h, params)

//@ forward_normal_at_hit  forward differences reusing the march's last estimate
forward_normal(p, here, h, params)

//@ uniform_values  a kernel writing point-independent values (a scene's bound) into `out`, one work-item
__kernel void uniform_values(__constant scalar *params, __global scalar *out) {
${body}${stores}}

//@ uniform_store
    out[$index] = (scalar)$value;
