// Templates of the direct renderer's `shade` (fractalc/emit.py
// `_shade_function`), which the emitter writes per scene: Blinn-Phong over
// every light of the scene, each light's block unrolled with its values,
// shadows and AO only where the scene asks for them. A `//@ NAME` line
// opens the template NAME (the rest of that line says what it is); `$name`
// marks where the emitter writes a value (fractalc/stdlib.py `templates`).

//@ signature  `shade`: the shaded colour at a hit
vec3 shade(vec3 p, vec3 normal, vec3 dir, real threshold, real steps, mask hit,
           PARAMS_SPACE scalar *params) {

//@ passes_signature  `shade_passes`: the same, filling in the shading passes
typedef struct {
    vec3 diffuse, specular;   // diffuse + specular = the shaded colour
    real shadow, occlusion;
} shading_passes;

vec3 shade_passes(vec3 p, vec3 normal, vec3 dir, real threshold, real steps, mask hit,
           PARAMS_SPACE scalar *params, shading_passes *passes) {

//@ surface  the hit's material, seen from the eye
    surface s = surface_at(p, params);
    vec3 albedo = v3(s.red, s.green, s.blue);
    vec3 to_eye = v3(-dir.x, -dir.y, -dir.z);

//@ step_occlusion  AO from the march's step count
    real occlusion = step_occlusion(steps, $strength);

//@ ambient_occlusion  AO sampled along the normal
    real occlusion = ambient_occlusion(p, normal, $delta, $strength, params);

//@ ambient  the constant ambient light
    vec3 color = v3_scale(albedo, $ambient);

//@ ambient_occluded
    vec3 color = v3_scale(albedo, $ambient * occlusion);

//@ ambient_environment  the environment's diffuse light replaces the constant one
    vec3 color = v3_mul(albedo, environment_light(normal));

//@ ambient_environment_occluded
    vec3 color = v3_mul(albedo, v3_scale(environment_light(normal), occlusion));

//@ passes_start  the passes before the lights: the ambient light is diffuse
    passes->diffuse = color;
    passes->specular = v3((real)0.0f, 0.0f, 0.0f);
    passes->shadow = 0.0f;
    passes->occlusion = $occlusion;

//@ shadow_start  where shadow rays start, and the bound that ends them
    vec3 lifted = v3_add(p, v3_scale(normal, 2.0f * threshold));

//@ shadow_bound
    vec3 bound_centre;
    real bound_radius = scene_bound(params, &bound_centre);

//@ headlight  no light in the scene
    // nothing lights the scene: a headlight, from the eye along the ray

//@ lit  a light's Blinn-Phong term, `radiance` arriving along `to_light`
    color = v3_add(color, blinn_phong(normal, $to_light, to_eye, albedo, s.specular, s.shininess, $radiance));

//@ lit_passes  the same, its highlight (the term without albedo) to the specular pass, the rest to diffuse
    vec3 lit = blinn_phong(normal, $to_light, to_eye, albedo, s.specular, s.shininess, $radiance);
    vec3 highlight = blinn_phong(normal, $to_light, to_eye, v3((real)0.0f, 0.0f, 0.0f), s.specular, s.shininess, $radiance);
    passes->specular = v3_add(passes->specular, highlight);
    passes->diffuse = v3_add(passes->diffuse, v3_sub(lit, highlight));
    color = v3_add(color, lit);

//@ light_start  one light's block
    {   // light $index: $kind, shadows $shadows

//@ light_from_direction  a light at infinity: `to_light` the unit vector toward it
        vec3 to_light = $to_light;
        real reach = (real)MAX_DISTANCE;
        vec3 radiance = $radiance;

//@ light_from_position  a light at a point, falling off with the inverse square of its distance (capped)
        vec3 offset = v3_sub($position, p);
        real reach = v3_length(offset);
        vec3 to_light = v3_scale(offset, 1.0f / reach);
        vec3 radiance = v3_scale($radiance, fmin(1.0f / (reach * reach), $max_inverse_square));

//@ spot_cone  smoothstep from the cone's outer cosine to its inner one (docs/looks.md#spot-lights)
        radiance = v3_scale(radiance, smoothstep($outer, $inner, -v3_dot(to_light, $axis)));

//@ rectangle_facing  a rectangle lights one side: the cosine at the light
        radiance = v3_scale(radiance, max(-v3_dot(to_light, $facing), 0.0f));

//@ shadow_ray_bound  where the shadow ray leaves the (widened) bound (two statements: C leaves the order of a call's arguments open)
        real enter, leave;
        mask toward_bound = ray_sphere_span(lifted, to_light, bound_centre, $widened, &enter, &leave);

//@ shadow_reach_bounded  the shadow ray ends where it leaves the bound
        reach = SELECT((real)0.0f, fmin(reach, leave), toward_bound);

//@ shadow_reach_bounded_unless_ground  ... unless it may meet a ground half-space
        reach = SELECT(reach, SELECT((real)0.0f, fmin(reach, leave), toward_bound), clear_of_half_spaces(lifted, to_light, threshold, params));

//@ hard_widening  a hard shadow's bound: blocked within the hit threshold, as a camera ray hits
bound_radius + threshold

//@ soft_widening  a soft shadow's bound, widened by (|o - c| + R) / (k - 1) (emit.py `_shadow_bound_radius`)
bound_radius + threshold + (v3_length(v3_sub(lifted, bound_centre)) + bound_radius) * $factor

//@ shadow_facing  a surface facing away from the light gets none of it (blinn_phong is 0 there): no shadow ray
        mask facing = hit & (v3_dot(normal, to_light) > 0.0f);

//@ hard_shadow  `$function`: hard_shadow, or hard_shadow_through where the scene has transparent solids
        real visible = $function(lifted, to_light, reach, threshold, facing, params);

//@ soft_shadow
        real visible = soft_shadow(lifted, to_light, reach, threshold, $softness, facing, params);

//@ shadowed
        radiance = v3_scale(radiance, visible);

//@ shadow_pass  the light the shadow takes
        passes->shadow = passes->shadow + (1.0f - visible);

//@ light_end
    }

//@ shadow_share  the fraction of the light the shadows take, averaged over the lights
    passes->shadow = passes->shadow * $share;

//@ end
    return color;
}

//@ discarding_passes  `shade` as `shade_passes` with the passes thrown away (the compiler drops them)
    shading_passes unused;
    return shade_passes(p, normal, dir, threshold, steps, hit, params, &unused);
}
