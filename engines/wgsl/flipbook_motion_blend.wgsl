// Ignis flipbook motion-vector blend (WGSL, wgpu / WebGPU). Same formula as
// ignis_media::write::motion::mv_blend and the engine shaders beside this one:
//   prev = sheet(frame k,   uv - mv_k(uv)   * t)
//   next = sheet(frame k+1, uv + mv_k+1(uv) * (1 - t))
//   out  = mix(prev, next, t),  mv = (rg * 2 - 1) * motion_scale   (tile-UV units)
// Written for the `generic` preset: UV origin top-left, green = +v down. Import the
// motion sheet as linear (Rgba16Unorm), the colour sheet as sRGB.

struct FlipbookParams {
    // columns, rows (the JSON's `columns` / `rows`)
    tiles: vec2<f32>,
    // frame_count from the JSON
    frames: f32,
    // motion_vectors.scale from the JSON
    motion_scale: f32,
    // playback position in frames: frame index + blend fraction
    time_frames: f32,
    // 1.0 when the JSON's `loop` is true
    looping: f32,
    _pad: vec2<f32>,
}

@group(0) @binding(0) var<uniform> params: FlipbookParams;
@group(0) @binding(1) var color_sheet: texture_2d<f32>;
@group(0) @binding(2) var motion_sheet: texture_2d<f32>;
@group(0) @binding(3) var sheet_sampler: sampler;

// Tile UV (0..1 over one cell, top-left origin) of sub-image `index` → sheet UV.
fn sheet_uv(tile_uv: vec2<f32>, index: f32) -> vec2<f32> {
    let row = floor(index / params.tiles.x);
    let col = index - row * params.tiles.x;
    return (vec2<f32>(col, row) + tile_uv) / params.tiles;
}

fn motion_at(tile_uv: vec2<f32>, index: f32) -> vec2<f32> {
    let rg = textureSample(motion_sheet, sheet_sampler, sheet_uv(tile_uv, index)).rg;
    return (rg * 2.0 - 1.0) * params.motion_scale;
}

fn flipbook_motion_blend(tile_uv: vec2<f32>) -> vec4<f32> {
    let f = floor(params.time_frames);
    let t = params.time_frames - f;
    let prev = f - params.frames * floor(f / params.frames);
    let wrapped = select(params.frames - 1.0, 0.0, params.looping > 0.5);
    let next = select(prev + 1.0, wrapped, prev + 1.0 >= params.frames);
    let mv_prev = motion_at(tile_uv, prev);
    let mv_next = motion_at(tile_uv, next);
    let a = textureSample(color_sheet, sheet_sampler, sheet_uv(tile_uv - mv_prev * t, prev));
    let b = textureSample(color_sheet, sheet_sampler, sheet_uv(tile_uv + mv_next * (1.0 - t), next));
    return mix(a, b, t);
}

@fragment
fn fs_main(@location(0) uv: vec2<f32>) -> @location(0) vec4<f32> {
    return flipbook_motion_blend(uv);
}
