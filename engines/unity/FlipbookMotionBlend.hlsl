// Ignis flipbook motion-vector blend: a Shader Graph Custom Function (File mode, function
// name "FlipbookMotionBlend", precision float) for sheets exported with `--engine unity`.
// The VFX Graph "Flipbook Motion Blend" formula (ignis_media::write::motion::mv_blend):
//   prev = sheet(frame k,   uv - mv_k(uv)   * t)
//   next = sheet(frame k+1, uv + mv_k+1(uv) * (1 - t))
//   out  = lerp(prev, next, t),  mv = (rg * 2 - 1) * MotionScale   (tile-UV units)
// Unity UVs start bottom-left (the Shader Graph Flipbook node's "Invert Y"): sub-image 0 is
// the top-left cell and green = +v up. Inputs: Tiles = (Tiles X, Tiles Y) from the JSON,
// Frames = frame_count, MotionScale = motion_vectors.scale, Time = frame + blend.
// Import the motion sheet with sRGB off, compression None. Uses bare Texture2D /
// SamplerState inputs ("Use bare types" / legacy Shader Graph texture inputs).

float2 IgnisSheetUV(float2 tileUV, float index, float2 tiles)
{
    float rowFromTop = floor(index / tiles.x);
    float col = index - rowFromTop * tiles.x;
    float rowFromBottom = tiles.y - 1.0 - rowFromTop;
    return (float2(col, rowFromBottom) + tileUV) / tiles;
}

void FlipbookMotionBlend_float(Texture2D ColorSheet, Texture2D MotionSheet, SamplerState Sampler,
                               float2 UV, float2 Tiles, float Frames, float MotionScale,
                               float Time, float Loop, out float4 Out)
{
    float f = floor(Time);
    float t = Time - f;
    float prev = f - Frames * floor(f / Frames);
    float next = prev + 1.0;
    if (next >= Frames)
        next = Loop > 0.5 ? 0.0 : Frames - 1.0;
    float2 mvPrev = (MotionSheet.Sample(Sampler, IgnisSheetUV(UV, prev, Tiles)).rg * 2.0 - 1.0) * MotionScale;
    float2 mvNext = (MotionSheet.Sample(Sampler, IgnisSheetUV(UV, next, Tiles)).rg * 2.0 - 1.0) * MotionScale;
    float4 a = ColorSheet.Sample(Sampler, IgnisSheetUV(UV - mvPrev * t, prev, Tiles));
    float4 b = ColorSheet.Sample(Sampler, IgnisSheetUV(UV + mvNext * (1.0 - t), next, Tiles));
    Out = lerp(a, b, t);
}
