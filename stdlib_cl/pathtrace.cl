// Monte Carlo path tracing (render key `integrator: path`; docs/looks.md).
// Spliced after the template by the emitter (fractalc/pathtrace.py), only
// into kernels of scenes that use it; the template calls `path_color` for
// every sample, and has `environment` (the sky) for it. Above this file, fractalc/pathtrace.py defines:
//   BOUNCES                 the most surface scatterings of a path
//   CAMERA_SEES_ENVIRONMENT 1, or 0 with a transparent background
//   PATH_TRANSPARENCY       1 where a material is transparent (the template
//                           then has through_solid)
//   LIGHT_COUNT, LIGHTS[]   LIGHT_STRIDE numbers per light, each field at
//                           its offset LIGHT_KIND, LIGHT_VECTOR, ...
//                           (lights.LIGHT_FIELDS says what they hold);
//                           its kind one of the codes LIGHT_IS_POINT, ...
//   AREA_LIGHTS             1 where a light is a sphere or a rectangle
//   MAX_INVERSE_SQUARE      the cap of a light's 1 / d^2 (as the direct renderer's)
//   MIS                     1: light that both next-event estimation and the
//                           surface's lobes can find is weighted between them
//                           (the power heuristic); 0: next-event estimation's
//                           alone (fractalc/pathtrace.py, for comparison)
// Paths scatter off surfaces in a loop (no recursion): at each hit, light
// from every light by next-event estimation (shadow rays), then one new
// direction sampled from the surface's lobes, which may meet a sphere or
// rectangle light or escape to the environment. Light that both ways find
// (area lights, an environment map) is counted by each with its multiple
// importance sampling weight; point, spot and directional lights only by
// the first, the sky gradient only by the second.

#define INV_PI 0.3183098861837907f
#define ROULETTE_AFTER 2        // bounces before Russian roulette may end a path
#define SMALLEST_ROUGHNESS 0.02f

// A uniform number in [0, 1) for this sample's `dimension` (every random
// decision of a path has its own).
real sample_random(lane_uint key, uint dimension) {
    return unit_random(hash_lanes(key + dimension * 0x9e3779b9u));
}

// `v` (x, y along two tangents, z along n) in world space: the tangents of
// Duff et al. 2017 ("Building an orthonormal basis, revisited").
vec3 around_normal(vec3 n, vec3 v) {
    real side = SELECT((real)-1.0f, (real)1.0f, n.z >= 0.0f);
    real a = -1.0f / (side + n.z);
    real b = n.x * n.y * a;
    vec3 t1 = v3(1.0f + side * n.x * n.x * a, side * b, -side * n.x);
    vec3 t2 = v3(b, side + n.y * n.y * a, -n.y);
    return v3_add(v3_add(v3_scale(t1, v.x), v3_scale(t2, v.y)), v3_scale(n, v.z));
}

// The Fresnel reflectance of a smooth dielectric (unpolarised light, the
// exact equations) for light meeting it from outside at cosine c to the
// normal, the inside's index of refraction `ior` (the outside's 1).
real fresnel_dielectric(real c, real ior) {
    c = clamp(c, 0.0f, 1.0f);
    real cos_t = sqrt(max(1.0f - (1.0f - c * c) / (ior * ior), 0.0f));   // Snell: sin_t = sin_i / ior
    real s = (c - ior * cos_t) / (c + ior * cos_t);
    real p = (cos_t - ior * c) / (cos_t + ior * c);
    return 0.5f * (s * s + p * p);
}

// Smith's masking of GGX for one direction at cosine c to the normal.
real smith_ggx(real c, real alpha) {
    real a2 = alpha * alpha;
    return 2.0f * c / (c + sqrt(a2 + (1.0f - a2) * c * c));
}

// GGX's distribution of microfacet normals at cosine nh to the normal.
real ggx_distribution(real nh, real alpha) {
    real a2 = alpha * alpha;
    real denominator = nh * nh * (a2 - 1.0f) + 1.0f;
    return a2 * INV_PI / (denominator * denominator);
}

// The GGX (Trowbridge-Reitz) microfacet reflection, white (no Fresnel: the
// direct renderer's highlight is white too), for n.l, n.v > 0.
real ggx_brdf(vec3 n, vec3 to_light, vec3 to_eye, real alpha) {
    vec3 h = v3_normalize(v3_add(to_light, to_eye));
    real nh = max(v3_dot(n, h), 0.0f), nl = v3_dot(n, to_light), nv = v3_dot(n, to_eye);
    return ggx_distribution(nh, alpha) * smith_ggx(nl, alpha) * smith_ggx(nv, alpha) / (4.0f * nl * nv);
}

// The density per steradian with which the surface's diffuse and glossy
// lobes draw the direction l (each lobe's density times its weight, as the
// lobe is chosen; the glossy lobe's half vector from D(h) n.h, so l's
// density is D(h) n.h / (4 v.h)). Mirror and glass draw single directions,
// which next-event estimation never draws.
real bsdf_density(vec3 n, vec3 to_eye, vec3 l, real diffuse_weight, real glossy_weight, real alpha) {
    vec3 h = v3_normalize(v3_add(l, to_eye));
    real nl = v3_dot(n, l), nh = max(v3_dot(n, h), 0.0f), vh = max(v3_dot(to_eye, h), (real)1e-6f);
    real glossy = SELECT((real)0.0f, ggx_distribution(nh, alpha) * nh / (4.0f * vh), v3_dot(n, to_eye) > 0.0f);
    return SELECT((real)0.0f, diffuse_weight * nl * INV_PI + glossy_weight * glossy, nl > 0.0f);
}

// The power heuristic (Veach 1997): the weight of a sample drawn with
// density `chosen` where another technique draws it with density `other`
// (1 / (1 + (other / chosen)^2): no overflow, 0 where chosen is 0).
real power_heuristic(real chosen, real other) {
    real ratio = fmin(other, (real)1e18f) / clamp(chosen, (real)1e-30f, (real)1e18f);
    return 1.0f / (1.0f + ratio * ratio);
}

// The weight of next-event estimation's sample of a light that the lobes
// can also find, drawn with `density` where the lobes' is `lobes`.
real light_sample_weight(real density, real lobes) {
#if MIS
    return power_heuristic(density, lobes);
#else
    return 1.0f;
#endif
}

// The weight of a light that a direction drawn by the lobes (with
// `density`) met, where next-event estimation draws it with
// `light_density`; 1 where the direction was not drawn by those lobes but
// is a camera ray's or a mirror's or glass's (`delta`: next-event
// estimation cannot find such light).
real lobe_sample_weight(real density, real light_density, mask delta) {
#if MIS
    return SELECT(power_heuristic(density, light_density), (real)1.0f, delta);
#else
    return SELECT((real)0.0f, (real)1.0f, delta);
#endif
}

#if ENVIRONMENT_MAP
// One direction drawn from the map's tables for one lane (u1 picks the
// row, u2 the column, u3 and u4 a point of the texel, uniform in solid
// angle): the direction in `direction`, its density per steradian in
// *density; returns the texel.
int draw_texel(scalar u1, scalar u2, scalar u3, scalar u4, scalar *direction, scalar *density) {
    int row = 0, column = 0;
    while (row < MAP_HEIGHT - 1 && ENVIRONMENT_ROWS[row] <= u1)
        row++;
    __constant float *columns = ENVIRONMENT_COLUMNS + row * MAP_WIDTH;
    while (column < MAP_WIDTH - 1 && columns[column] <= u2)
        column++;
    scalar longitude = ((scalar)column + u3) * (2.0f * PI_F / MAP_WIDTH) - PI_F;
    scalar top = cos((scalar)row * (PI_F / MAP_HEIGHT)), bottom = cos((scalar)(row + 1) * (PI_F / MAP_HEIGHT));
    scalar z = top - u4 * (top - bottom);
    scalar across = sqrt(max(1.0f - z * z, 0.0f));
    direction[0] = across * cos(longitude);
    direction[1] = across * sin(longitude);
    direction[2] = z;
    *density = ENVIRONMENT_DENSITY[row * MAP_WIDTH + column];
    return row * MAP_WIDTH + column;
}

// A direction toward the environment map per lane, drawn in proportion to
// its brightness (random dimensions first .. first + 3): the direction and
// its radiance in *dir and *radiance; returns its density per steradian.
real sample_environment(lane_uint key, uint first, vec3 *dir, vec3 *radiance) {
    scalar u[4][LANES], x[LANES], y[LANES], z[LANES], red[LANES], green[LANES], blue[LANES], density[LANES];
    for (uint k = 0; k < 4u; k++)
        STORE_LANES(sample_random(key, first + k), 0, u[k]);
    for (int i = 0; i < LANES; i++) {
        scalar direction[3];
        int texel = 3 * draw_texel(u[0][i], u[1][i], u[2][i], u[3][i], direction, &density[i]);
        x[i] = direction[0], y[i] = direction[1], z[i] = direction[2];
        red[i] = ENVIRONMENT_TEXELS[texel], green[i] = ENVIRONMENT_TEXELS[texel + 1];
        blue[i] = ENVIRONMENT_TEXELS[texel + 2];
    }
    *dir = v3(LOAD_LANES(0, x), LOAD_LANES(0, y), LOAD_LANES(0, z));
    *radiance = v3(LOAD_LANES(0, red), LOAD_LANES(0, green), LOAD_LANES(0, blue));
    return LOAD_LANES(0, density);
}
#endif

// The vector of a light's table row at `field` (LIGHT_VECTOR, LIGHT_AXIS, ...).
vec3 light_vec3(__constant scalar *light, int field) {
    return v3(light[field], light[field + 1], light[field + 2]);
}

// Its squared length, in scalars.
scalar light_length2(__constant scalar *light, int field) {
    return light[field] * light[field] + light[field + 1] * light[field + 1] + light[field + 2] * light[field + 2];
}

// Whether a light has an area that rays may meet: a sphere or a rectangle.
bool is_area_light(__constant scalar *light) {
    return light[LIGHT_KIND] == LIGHT_IS_SPHERE || light[LIGHT_KIND] == LIGHT_IS_RECTANGLE;
}

// A rectangle light's area: the lengths of its two (perpendicular) edges.
scalar rectangle_area(__constant scalar *light) {
    return sqrt(light_length2(light, LIGHT_WIDTH) * light_length2(light, LIGHT_HEIGHT));
}

#if AREA_LIGHTS
// The radiance of the nearest sphere or rectangle light (the lit side of a
// rectangle; from behind it is not there) that the ray from `origin` along
// `dir` meets before `reach`, weighted for the way the ray was drawn
// (lobe_sample_weight, with the lobes' `density` or `delta`; a light that
// casts no shadows is next-event estimation's alone); *seen: the lanes that
// meet one. The light numbered `skip` is not looked for (-1: none).
vec3 area_light_seen(vec3 origin, vec3 dir, real reach, real density, mask delta, int skip, mask *seen) {
    vec3 emitted = v3((real)0.0f, 0.0f, 0.0f);
    real nearest = reach;
    *seen = (mask)0;
    for (int i = 0; i < LIGHT_COUNT; i++) {
        __constant scalar *light = LIGHTS + i * LIGHT_STRIDE;
        if (!is_area_light(light) || i == skip)
            continue;
        vec3 offset = v3_sub(light_vec3(light, LIGHT_VECTOR), origin);
        real t, light_density;
        mask met;
        scalar area;
        if (light[LIGHT_KIND] == LIGHT_IS_SPHERE) {
            // the ball's near side, seen from outside it; next-event
            // estimation draws directions uniformly in the cone it fills
            scalar radius = light[LIGHT_RADIUS];
            real along = v3_dot(offset, dir), distance2 = v3_dot(offset, offset);
            real discriminant = along * along - distance2 + radius * radius;
            t = along - sqrt(max(discriminant, 0.0f));
            met = (discriminant >= 0.0f) & (distance2 > radius * radius) & (t > 0.0f);
            real sin2 = fmin(radius * radius / distance2, 1.0f);
            light_density = 1.0f / (6.283185307179586f * max(sin2 / (1.0f + sqrt(1.0f - sin2)), (real)1e-30f));
            area = PI_F * radius * radius;      // the radiance is irradiance / (pi r^2)
        } else {
            // the panel's plane, within its edges; next-event estimation
            // draws points uniformly on it (density d^2 / (area cos))
            vec3 axis = light_vec3(light, LIGHT_AXIS);
            vec3 width = light_vec3(light, LIGHT_WIDTH), height = light_vec3(light, LIGHT_HEIGHT);
            real facing = -v3_dot(dir, axis);
            t = v3_dot(offset, axis) / SELECT(-facing, (real)-1.0f, facing == 0.0f);
            vec3 on_plane = v3_sub(v3_scale(dir, t), offset);
            real s = v3_dot(on_plane, width) / v3_dot(width, width);
            real u = v3_dot(on_plane, height) / v3_dot(height, height);
            met = (facing > 0.0f) & (t > 0.0f) & (fabs(s) <= 0.5f) & (fabs(u) <= 0.5f);
            area = rectangle_area(light);
            light_density = t * t / max(area * facing, (real)1e-30f);
        }
        met = met & (t < nearest);
        real weight = light[LIGHT_SHADOWS] != 0.0f ? lobe_sample_weight(density, light_density, delta)
                                       : SELECT((real)0.0f, (real)1.0f, delta);
        vec3 radiance = v3_scale(light_vec3(light, LIGHT_IRRADIANCE), weight / area);
        emitted = v3_select(emitted, radiance, met);
        nearest = SELECT(nearest, t, met);
        *seen = *seen | met;
    }
    return emitted;
}
#endif

// Light arriving at p from every light, reflected toward the eye:
// next-event estimation with a shadow ray per light that casts shadows
// (a sphere light's toward a point of it drawn with random dimensions
// `first + 2 i` and `first + 2 i + 1`).
vec3 direct_light(vec3 p, vec3 lifted, vec3 n, vec3 to_eye, vec3 eye, vec3 albedo, real diffuse_weight,
                  real glossy_weight, real alpha, mask active, lane_uint key, uint first, scalar pixel_angle,
                  PARAMS_SPACE scalar *params) {
    vec3 total = v3((real)0.0f, 0.0f, 0.0f);
    for (int i = 0; i < LIGHT_COUNT; i++) {
        __constant scalar *light = LIGHTS + i * LIGHT_STRIDE;
        vec3 vector = light_vec3(light, LIGHT_VECTOR);
        vec3 to_light = vector;
        real reach = (real)MAX_DISTANCE, falloff = 1.0f;
        real light_density = 0.0f;     // an area light's density of its sampled direction
        if (light[LIGHT_KIND] != LIGHT_IS_DIRECTIONAL) {
            bool headlight = light[LIGHT_KIND] == LIGHT_IS_HEADLIGHT;
            vec3 offset = v3_sub(headlight ? eye : vector, p);
            reach = v3_length(offset);
            to_light = v3_scale(offset, 1.0f / max(reach, (real)1e-30f));
            if (!headlight)
                falloff = fmin(1.0f / (reach * reach), MAX_INVERSE_SQUARE);
            if (light[LIGHT_KIND] == LIGHT_IS_SPOT)   // a spot's cone: smoothstep across its falloff
                falloff = falloff * smoothstep(light[LIGHT_CONE_OUTER], light[LIGHT_CONE_INNER],
                                               -v3_dot(to_light, light_vec3(light, LIGHT_AXIS)));
            if (light[LIGHT_KIND] == LIGHT_IS_SPHERE) {
                // a sphere light of radiance irradiance / (pi r^2): a direction
                // uniform in the cone the sphere fills, weighted by the cone's
                // solid angle 2 pi (1 - cos_max) (1 / d^2 from afar, as a point)
                scalar radius = light[LIGHT_RADIUS];
                real sin2 = fmin(radius * radius / (reach * reach), 1.0f);
                real cos_max = sqrt(1.0f - sin2);
                real one_minus_cos = sin2 / (1.0f + cos_max);     // 1 - cos_max, exact for a small sphere
                real cos_t = 1.0f - sample_random(key, first + 2u * (uint)i) * one_minus_cos;
                real sin_t = sqrt(max(1.0f - cos_t * cos_t, 0.0f));
                real angle = 6.283185307179586f * sample_random(key, first + 2u * (uint)i + 1u);
                falloff = SELECT(2.0f * one_minus_cos / (radius * radius), (real)0.0f, reach <= radius);
                light_density = 1.0f / (6.283185307179586f * max(one_minus_cos, (real)1e-30f));
                reach = reach * cos_t - sqrt(max(radius * radius - reach * reach * sin_t * sin_t, 0.0f));
                to_light = around_normal(to_light, v3(sin_t * cos(angle), sin_t * sin(angle), cos_t));
            }
            if (light[LIGHT_KIND] == LIGHT_IS_RECTANGLE) {
                // a rectangle of radiance irradiance / area, lighting the side
                // its axis faces: a point uniform on it, weighted by the
                // cosine there over the squared distance
                real s = sample_random(key, first + 2u * (uint)i) - 0.5f;
                real t = sample_random(key, first + 2u * (uint)i + 1u) - 0.5f;
                vec3 point = v3_add(vector, v3_add(v3_scale(light_vec3(light, LIGHT_WIDTH), s),
                                                   v3_scale(light_vec3(light, LIGHT_HEIGHT), t)));
                vec3 offset = v3_sub(point, p);
                reach = v3_length(offset);
                to_light = v3_scale(offset, 1.0f / max(reach, (real)1e-30f));
                real facing = -v3_dot(to_light, light_vec3(light, LIGHT_AXIS));
                falloff = fmin(max(facing, 0.0f) / (reach * reach), MAX_INVERSE_SQUARE);
                light_density = reach * reach / max(rectangle_area(light) * facing, (real)1e-30f);
            }
        }
        real cosine = v3_dot(n, to_light);
        mask lit = active & (cosine > 0.0f);
        if (!ANY(lit))
            continue;
        if (light[LIGHT_SHADOWS] != 0.0f) {
            COUNT_MARCH(COUNT_SHADOWS);
            march_result blocker = march(lifted, to_light, lit, pixel_angle, 0.0f, params);
            lit = lit & !(blocker.hit & (blocker.t < reach));
#if AREA_LIGHTS
            // area lights are opaque: one before this light hides it, as
            // from the lobes' directions
            mask hidden;
            area_light_seen(p, to_light, reach, 0.0f, ~(mask)0, i, &hidden);
            lit = lit & !hidden;
#endif
        }
        // (only where both the light and the eye face the surface: elsewhere
        // Smith's masking divides by zero, and 0 times that is not 0)
        real glossy = SELECT((real)0.0f, ggx_brdf(n, to_light, to_eye, alpha), lit & (v3_dot(n, to_eye) > 0.0f));
        // irradiance E times the BRDF (albedo / pi diffuse, plus the glossy lobe) times the cosine
        vec3 reflected = v3_add(v3_scale(albedo, diffuse_weight * INV_PI), v3((real)(glossy_weight * glossy),
                                glossy_weight * glossy, glossy_weight * glossy));
        real strength = SELECT((real)0.0f, cosine * falloff, lit);
        if (is_area_light(light) && light[LIGHT_SHADOWS] != 0.0f)   // the lobes find it too
            strength = strength * light_sample_weight(light_density, bsdf_density(n, to_eye, to_light,
                                                                                   diffuse_weight, glossy_weight, alpha));
        total = v3_add(total, v3_mul(reflected, v3_scale(light_vec3(light, LIGHT_IRRADIANCE), strength)));
    }
#if ENVIRONMENT_MAP
    // the environment map as a light: one direction drawn by its
    // brightness, radiance times the BRDF times the cosine over the density
    vec3 to_sky, sky;
    real density = sample_environment(key, first + 2u * (uint)LIGHT_COUNT, &to_sky, &sky);
    real cosine = v3_dot(n, to_sky);
    mask lit = active & (cosine > 0.0f) & (density > 0.0f);
    if (ANY(lit)) {
        COUNT_MARCH(COUNT_SHADOWS);
        march_result blocker = march(lifted, to_sky, lit, pixel_angle, 0.0f, params);
        lit = lit & !blocker.hit;
#if AREA_LIGHTS
        mask hidden;      // behind an area light
        area_light_seen(p, to_sky, (real)1e30f, 0.0f, ~(mask)0, -1, &hidden);
        lit = lit & !hidden;
#endif
        real glossy = SELECT((real)0.0f, ggx_brdf(n, to_sky, to_eye, alpha), lit & (v3_dot(n, to_eye) > 0.0f));
        vec3 reflected = v3_add(v3_scale(albedo, diffuse_weight * INV_PI), v3((real)(glossy_weight * glossy),
                                glossy_weight * glossy, glossy_weight * glossy));
        real strength = SELECT((real)0.0f, cosine / max(density, (real)1e-30f), lit)
                        * light_sample_weight(density, bsdf_density(n, to_eye, to_sky, diffuse_weight, glossy_weight,
                                                                    alpha));
        total = v3_add(total, v3_mul(reflected, v3_scale(sky, strength)));
    }
#endif
    return total;
}

// The radiance one camera sample brings back along `dir` from `origin`,
// whose march `m` hit where `normal` says (or missed).
vec3 path_color(vec3 origin, vec3 dir, march_result m, vec3 normal, scalar pixel_angle, lane_uint key,
                PARAMS_SPACE scalar *params) {
    vec3 eye = origin;
    vec3 radiance = v3_scale(environment(dir), SELECT((real)CAMERA_SEES_ENVIRONMENT, (real)0.0f, m.hit));
    vec3 throughput = v3((real)1.0f, 1.0f, 1.0f);
    mask active = m.hit;
#if AREA_LIGHTS
    // a light in front of what the camera ray hit, or where it missed
    mask seen;
    vec3 emitted = area_light_seen(origin, dir, SELECT((real)1e30f, m.t, m.hit), 0.0f, ~(mask)0, -1, &seen);
#if !CAMERA_SEES_ENVIRONMENT
    seen = seen & m.hit;     // a miss is empty, lights included
#endif
    radiance = v3_select(radiance, emitted, seen);
    active = active & !seen;
#endif
    real travelled = 0.0f;
    for (int bounce = 0; bounce < BOUNCES && ANY(active); bounce++) {
        travelled = travelled + m.t;
        vec3 p = v3_add(origin, v3_scale(dir, m.t));
        surface s = surface_at(p, params);
        vec3 albedo = v3(s.red, s.green, s.blue);
        vec3 to_eye = v3_scale(dir, -1.0f);
        // the distance's gradient, outward (not turned toward the ray: a
        // grazing ray stops short of the surface, where it may face away)
        vec3 n = normal;
        // the material's lobes: mirror (reflectivity), clear glass
        // (transparency), glossy GGX (specular, roughness from shininess as
        // for Blinn-Phong), diffuse (the rest)
        real mirror_weight = clamp(s.reflectivity, 0.0f, 1.0f);
        real glass_weight = (1.0f - mirror_weight) * clamp(s.transparency, 0.0f, 1.0f);
        real glossy_weight = (1.0f - mirror_weight - glass_weight) * clamp(s.specular, 0.0f, 1.0f);
        real diffuse_weight = 1.0f - mirror_weight - glass_weight - glossy_weight;
        real alpha = max(sqrt(2.0f / (s.shininess + 2.0f)), SMALLEST_ROUGHNESS);
        real threshold = hit_threshold(travelled, pixel_angle);
        vec3 lifted = v3_add(p, v3_scale(n, 2.0f * threshold));
        radiance = v3_add(radiance, v3_mul(throughput, direct_light(p, lifted, n, to_eye, eye, albedo, diffuse_weight,
                                                                     glossy_weight, alpha, active, key,
                                                                     1000u + (uint)bounce * 256u, pixel_angle, params)));
        // one lobe, chosen by its weight, samples the next direction; the
        // throughput takes the lobe's f cos / pdf (its weight cancels)
        uint first = (uint)bounce * 4u + 1u;
        real choice = sample_random(key, first), u = sample_random(key, first + 1u);
        real angle = 6.283185307179586f * sample_random(key, first + 2u);
        mask diffuse = choice < diffuse_weight;
        mask glossy = !diffuse & (choice < diffuse_weight + glossy_weight);
        // diffuse: cosine-weighted about n; f cos / pdf = albedo
        real radius = sqrt(u);
        vec3 scattered = around_normal(n, v3(radius * cos(angle), radius * sin(angle), sqrt(max(1.0f - u, 0.0f))));
        vec3 weight = albedo;
        // glossy: the half vector from GGX's D(h) cos; f cos / pdf = G (v.h) / (n.v n.h)
        real tan2 = alpha * alpha * u / max(1.0f - u, (real)1e-7f);
        real cos_h = rsqrt(1.0f + tan2), sin_h = sqrt(max(1.0f - cos_h * cos_h, 0.0f));
        vec3 h = v3_select(n, around_normal(n, v3(sin_h * cos(angle), sin_h * sin(angle), cos_h)), glossy);
        real vh = v3_dot(to_eye, h);
        vec3 reflected = v3_sub(v3_scale(h, 2.0f * vh), to_eye);   // the mirror lobe: h = n
        real nv = v3_dot(n, to_eye), nl = v3_dot(n, reflected);
        // G(v) / n.v written out: bounded (by 2 / alpha) where n.v is tiny
        real a2 = alpha * alpha;
        real masking_over_nv = 2.0f / (nv + sqrt(a2 + (1.0f - a2) * nv * nv));
        real glossy_weight_now = masking_over_nv * smith_ggx(max(nl, 0.0f), alpha) * vh / max(v3_dot(n, h), 1e-6f);
        // only reflections from the eye's side to the eye's side (a grazing
        // ray stops short of the surface, where n.v may be negative)
        mask reflects = (nv > 0.0f) & (nl > 0.0f) & (vh > 0.0f);
        real specular_weight = SELECT((real)0.0f, SELECT((real)1.0f, glossy_weight_now, glossy), reflects);
        scattered = v3_select(reflected, scattered, diffuse);
        weight = v3_select(v3(specular_weight, specular_weight, specular_weight), weight, diffuse);
        vec3 start = lifted;
#if PATH_TRANSPARENCY
        // glass: reflected with the probability of its Fresnel reflectance
        // (the mirror direction above, weight 1), else through the solid (the
        // direct renderer's through_solid), white, on from its far side; the
        // glass band of `choice`, rescaled, is the draw between the two. A ray
        // that meets the surface from behind (a grazing ray stopped short of
        // it) goes through.
        real glass_start = diffuse_weight + glossy_weight;
        mask glass = active & !diffuse & !glossy & (choice < glass_start + glass_weight);
        real reflectance = SELECT((real)0.0f, fresnel_dielectric(nv, s.ior), nv > 0.0f);
        mask through = glass & ((choice - glass_start) >= reflectance * glass_weight);
        if (ANY(through)) {
            vec3 out_start;
            vec3 out_dir = through_solid(p, dir, n, s.ior, threshold, through, &out_start, params);
            scattered = v3_select(scattered, out_dir, through);
            start = v3_select(start, out_start, through);
            weight = v3_select(weight, v3((real)1.0f, 1.0f, 1.0f), through);
        }
#endif
        throughput = v3_mul(throughput, weight);
        // how the direction was drawn, for the weights of the light it meets
        mask delta = !diffuse & !glossy;
        real density = bsdf_density(n, to_eye, scattered, diffuse_weight, glossy_weight, alpha);
        // Russian roulette: a dim path goes on with the probability of its
        // brightness, and if it does, counts for the ones that stopped
        if (bounce >= ROULETTE_AFTER) {
            real going_on = clamp(max(throughput.x, max(throughput.y, throughput.z)), 0.0f, 0.95f);
            active = active & (sample_random(key, first + 3u) < going_on);
            throughput = v3_scale(throughput, 1.0f / max(going_on, (real)1e-6f));
        }
        active = active & (max(throughput.x, max(throughput.y, throughput.z)) > 0.0f);
        COUNT_MARCH(COUNT_REFLECTIONS);     // a bounce is a reflected ray
        m = march(start, scattered, active, pixel_angle, 0.0f, params);
#if AREA_LIGHTS
        // a light that the new direction meets before the next surface: its
        // weighted radiance, and the path ends there. Seen from the hit
        // itself, not from the lifted start of the march: next-event
        // estimation's directions, and their densities, are the hit's
        // (the lift is a few pixel footprints, far from small near a
        // light); a glass path's from where it left the solid.
        mask seen;
        vec3 emitted = area_light_seen(v3_select(p, start, delta), scattered, SELECT((real)1e30f, m.t, m.hit),
                                       density, delta, -1, &seen);
        seen = seen & active;
        radiance = v3_add(radiance, v3_mul(throughput, v3_select(v3((real)0.0f, 0.0f, 0.0f), emitted, seen)));
        active = active & !seen;
#endif
        mask escaped = active & !m.hit;
#if ENVIRONMENT_MAP
        // a map's light is next-event estimation's too: weighted between them
        real sky_weight = lobe_sample_weight(density, table_at(ENVIRONMENT_DENSITY, map_texel(scattered)), delta);
#else
        real sky_weight = 1.0f;
#endif
        radiance = v3_add(radiance, v3_mul(throughput, v3_scale(environment(scattered),
                                                                SELECT((real)0.0f, sky_weight, escaped))));
        active = active & m.hit;
        normal = hit_normal(start, scattered, m, pixel_angle, params);
        origin = start;
        dir = scattered;
    }
    return radiance;
}
