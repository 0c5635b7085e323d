// Coke bed preheating of a Hall–Héroult cell: a 2D vertical slice along one cathode block,
// from the cell's centre line (x = 0, symmetry) to the shell, through the collector bar's
// middle plane. Every body is a rectangle; the model's out-of-plane widths (the block's 0.48 m,
// the bar's 0.16 m, the slot's 0.2 m) are the demo's (demos/demo_preheat.py).
//
// Dimensions and their sources:
//   cathode block: 3.67 m long (half: 1.835 m), 0.48 m high; slot 176 mm high, 200 mm wide
//     (mean), 16 mm of cast iron above a 160 mm × 160 mm bar; bars of 2.175 m starting 0.1 m
//     from the block's middle (a middle section without bar): M. Dupuis, "Development and
//     application of an ANSYS based thermo-electro-mechanical collector bar slot design tool",
//     Light Metals 2011, as geo/collector_bar_slot.geo. The bar's end is 0.44 m beyond the
//     block's end.
//   coke bed: 20 mm (the parameter coke; 20 and 30 mm are the thicknesses compared in a
//     160 kA preheat study, docs/research/hall-heroult-materials.md §4).
//   Choices of this model (typical prebake cells; no single source read): anodes 1.55 m long
//     and 0.6 m high, a 0.2 m centre channel (anodes from x = 0.1 m), three stubs of 0.18 m
//     on each anode's top (the current entry), a peripheral ramming paste seam 0.25 m wide
//     at the block's end, up to the block's top, on the bar (which runs through it).
//   Not in the slice: the carbon beside the slot (out of the slot's plane), the lining under
//     the block and the cover above the anodes (boundary conditions in the demo).
//
// Axes: x along the block from the cell's centre line, y up from the bar's bottom (the
// block's bottom) to the anodes' top.
//
// Physical groups (names are what the Python scripts use):
//   anode, coke, block, cast_iron, bar, paste     the bodies
//   anode_coke        anode / coke bed (y = 0.48 + coke)
//   coke_block        coke bed / cathode block (y = 0.48, under the anode)
//   slot_top          cast iron / block (y = 0.176)
//   bar_top           bar / cast iron (y = 0.16)
//   block_paste       block end / ramming paste (x = 1.835)
//   iron_paste        cast iron end / ramming paste (x = 1.835)
//   bar_paste         bar / ramming paste (y = 0.16, beyond the block)
//   stubs             the anode top under the stubs (current entry)
//   anode_cover       the rest of the anode top (under the cover)
//   anode_sides       the anode's two ends (in the channels)
//   coke_sides        the coke bed's two ends
//   block_top         the block's top not under the coke bed (centre channel, side channel)
//   symmetry          x = 0 (the block)
//   slot_void         the block's face over the empty middle of the slot, the bar's and the
//                     cast iron's ends there (x = 0.1 m)
//   bottom            the bar's bottom (y = 0, on the lining)
//   paste_top         the ramming paste's top (side ledge)
//   sidewall          the ramming paste's outer face (x = 2.085)
//   bar_surface       the bar's top out of the paste (through the shell)
//   bar_end           the bar's end (current exit, x = 2.275)
//
// Parameters (override with load_scene(..., parameters={"size": 0.05})):
DefineConstant[ size = 0.08 ];      // element size away from the contacts [m]
DefineConstant[ fine = 0.02 ];      // element size on the contacts [m]
DefineConstant[ coke = 0.02 ];      // coke bed thickness [m]

SetFactory("OpenCASCADE");
half_length = 3.67 / 2;  height = 0.48;
slot_h = 0.176;  bar_h = 0.16;  x0 = 0.1;  bar_end = x0 + 2.175;
anode_x0 = 0.1;  anode_x1 = anode_x0 + 1.55;  anode_h = 0.6;
paste_w = 0.25;  stub_w = 0.18;
y_bed = height + coke;  y_top = y_bed + anode_h;
e = 1e-6;

Rectangle(1) = {0, slot_h, 0, half_length, height - slot_h};                 // block
Rectangle(2) = {x0, bar_h, 0, half_length - x0, slot_h - bar_h};             // cast iron
Rectangle(3) = {x0, 0, 0, bar_end - x0, bar_h};                              // bar
Rectangle(4) = {half_length, bar_h, 0, paste_w, height - bar_h};             // paste
Rectangle(5) = {anode_x0, height, 0, anode_x1 - anode_x0, coke};             // coke bed
Rectangle(6) = {anode_x0, y_bed, 0, anode_x1 - anode_x0, anode_h};           // anode
// the stubs' footprints on the anode's top: three, evenly spaced
pitch = (anode_x1 - anode_x0) / 3;
For i In {0 : 2}
  xs = anode_x0 + (i + 0.5) * pitch - stub_w / 2;
  Point(100 + 2 * i) = {xs, y_top, 0};
  Point(101 + 2 * i) = {xs + stub_w, y_top, 0};
EndFor
BooleanFragments{ Surface{1 : 6}; Delete; }{ Point{100 : 105}; Delete; }

Physical Surface("block") = Surface In BoundingBox{-e, slot_h - e, -e, half_length + e, height + e, e};
Physical Surface("cast_iron") = Surface In BoundingBox{x0 - e, bar_h - e, -e, half_length + e, slot_h + e, e};
Physical Surface("bar") = Surface In BoundingBox{x0 - e, -e, -e, bar_end + e, bar_h + e, e};
Physical Surface("paste") = Surface In BoundingBox{half_length - e, bar_h - e, -e, half_length + paste_w + e, height + e, e};
Physical Surface("coke") = Surface In BoundingBox{anode_x0 - e, height - e, -e, anode_x1 + e, y_bed + e, e};
Physical Surface("anode") = Surface In BoundingBox{anode_x0 - e, y_bed - e, -e, anode_x1 + e, y_top + e, e};

// Curves on a horizontal or vertical segment.
Macro Horizontal
  found[] = Curve In BoundingBox{xa - e, yh - e, -e, xb + e, yh + e, e};
Return
Macro Vertical
  found[] = Curve In BoundingBox{xv - e, ya - e, -e, xv + e, yb + e, e};
Return

xa = anode_x0; xb = anode_x1; yh = y_bed; Call Horizontal;
Physical Curve("anode_coke") = found[];
yh = height; Call Horizontal;
Physical Curve("coke_block") = found[];
xa = x0; xb = half_length; yh = slot_h; Call Horizontal;
Physical Curve("slot_top") = found[];
yh = bar_h; Call Horizontal;
Physical Curve("bar_top") = found[];
xv = half_length; ya = slot_h; yb = height; Call Vertical;
Physical Curve("block_paste") = found[];
ya = bar_h; yb = slot_h; Call Vertical;
Physical Curve("iron_paste") = found[];
xa = half_length; xb = half_length + paste_w; yh = bar_h; Call Horizontal;
Physical Curve("bar_paste") = found[];

stubs[] = {};
For i In {0 : 2}
  xa = anode_x0 + (i + 0.5) * pitch - stub_w / 2; xb = xa + stub_w; yh = y_top; Call Horizontal;
  stubs[] += found[];
EndFor
Physical Curve("stubs") = stubs[];
xa = anode_x0; xb = anode_x1; yh = y_top; Call Horizontal;
cover[] = found[];
cover[] -= stubs[];
Physical Curve("anode_cover") = cover[];
ends[] = {};
xv = anode_x0; ya = y_bed; yb = y_top; Call Vertical;
ends[] += found[];
xv = anode_x1; Call Vertical;
ends[] += found[];
Physical Curve("anode_sides") = ends[];
ends[] = {};
xv = anode_x0; ya = height; yb = y_bed; Call Vertical;
ends[] += found[];
xv = anode_x1; Call Vertical;
ends[] += found[];
Physical Curve("coke_sides") = ends[];
bare[] = {};
xa = 0; xb = anode_x0; yh = height; Call Horizontal;
bare[] += found[];
xa = anode_x1; xb = half_length; Call Horizontal;
bare[] += found[];
Physical Curve("block_top") = bare[];
xv = 0; ya = slot_h; yb = height; Call Vertical;
Physical Curve("symmetry") = found[];
void[] = {};
xa = 0; xb = x0; yh = slot_h; Call Horizontal;
void[] += found[];
xv = x0; ya = 0; yb = slot_h; Call Vertical;
void[] += found[];
Physical Curve("slot_void") = void[];
xa = x0; xb = bar_end; yh = 0; Call Horizontal;
Physical Curve("bottom") = found[];
xa = half_length; xb = half_length + paste_w; yh = height; Call Horizontal;
Physical Curve("paste_top") = found[];
xv = half_length + paste_w; ya = bar_h; yb = height; Call Vertical;
Physical Curve("sidewall") = found[];
xa = half_length + paste_w; xb = bar_end; yh = bar_h; Call Horizontal;
Physical Curve("bar_surface") = found[];
xv = bar_end; ya = 0; yb = bar_h; Call Vertical;
Physical Curve("bar_end") = found[];

// Sizes: fine on the contacts (and through the coke bed), coarse away from them.
Field[1] = Distance;
Field[1].CurvesList = {Curve In BoundingBox{anode_x0 - e, height - e, -e, anode_x1 + e, y_bed + e, e}};
Field[1].Sampling = 200;
Field[2] = Threshold;
Field[2].InField = 1;
Field[2].SizeMin = fine;
Field[2].SizeMax = size;
Field[2].DistMin = 0.02;
Field[2].DistMax = 0.3;
Field[3] = Distance;
Field[3].CurvesList = {Curve In BoundingBox{x0 - e, bar_h - e, -e, half_length + paste_w + e, slot_h + e, e}};
Field[3].Sampling = 200;
Field[4] = Threshold;
Field[4].InField = 3;
Field[4].SizeMin = fine;
Field[4].SizeMax = size;
Field[4].DistMin = 0.02;
Field[4].DistMax = 0.3;
Field[5] = Min;
Field[5].FieldsList = {2, 4};
Background Field = 5;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
Mesh.MeshSizeMax = size;
