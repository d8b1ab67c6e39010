"""Colour maps of the appearance states: read, checked, resampled and compressed in linear light.

A wrinkle state may carry a colour map beside its normal map (DESIGN.md section 1, "Appearance
states"): the face's albedo in that pose, 8- or 16-bit sRGB as painted. The model is
:func:`wrinklepipe.model.combine_color`; this package is the stages around it:

- :mod:`.read`: colour texels from files, and the checks that a colour map is not a normal
  map given in the wrong place (and the reverse);
- :mod:`.resample`: sizes in linear light;
- :mod:`.copies`: sRGB BC1 / BC7 copies with mips made in linear light.
"""
