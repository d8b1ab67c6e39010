"""The wrinkle model as shader code: one template emitted for every target.

:mod:`~wrinklepipe.shading.setup` describes an asset as a shader sees it (counts, mask groups,
the slot table that places region weights); :mod:`~wrinklepipe.shading.template` holds the core
(GLSL spelling, translated to HLSL and Godot's shading language); :mod:`~wrinklepipe.shading.glsl`
wraps it for the validator's render pass.
"""
