// Quarter of a Hall–Héroult cathode block with its collector bar sealed into the slot by cast
// iron (3D). After M. Dupuis, "Development and application of an ANSYS based thermo-electro-
// mechanical collector bar slot design tool", Light Metals 2011 (TMS), its "single slot per
// block" base case:
//   block 3.67 m long, 0.48 m × 0.48 m; two bars of 2.175 m per block, 160 mm × 160 mm;
//   slot 176 mm high, 200 mm wide on average, its vertical faces V-shaped: 15 mm of cast iron
//   at the thinnest, 25 mm at the thickest; 16 mm of cast iron above the bar.
// Choices of this model (not in the source): the V's apex at mid-height of the slot, the
// thinnest cast iron at its bottom and top; a 0.2 m middle section of the slot without bar and
// without cast iron (an empty slot: its faces are free), so that 0.44 m of each bar runs out
// of the block's end.
//
// Axes: x along the block from its middle (x = 0, symmetry) to its end (x = 1.835 m); y across
// the block from the slot's middle plane (y = 0, symmetry) to the block's side (y = 0.24 m);
// z up from the block's bottom (z = 0) to its top (z = 0.48 m, the metal pad side).
//
// Physical groups (names are what the Python scripts use):
//   block, cast_iron, bar          the bodies
//   slot_side                      cast iron / carbon, the two planes of the V (inclined)
//   slot_top                       cast iron / carbon, the slot's top face (z = slot_h)
//   bar_side, bar_top              bar / cast iron (y = bar_w, z = bar_h)
//   top                            the block's top face: current entry, bath side
//   block_end                      x = 1.835 m, the block's end and the cast iron's end face
//   block_side                     y = 0.24 m, the block's side
//   bottom                         z = 0 under the block, the cast iron and the bar in the block
//   symmetry_x                     x = 0 (the block)
//   symmetry_y                     y = 0 (every body)
//   bar_surface                    the bar's faces out of the block but its end
//   bar_end                        the bar's end (current exit)
//
// Parameters (override with load_scene(..., parameters={"size": 0.05})):
DefineConstant[ size = 0.08 ];      // element size away from the slot [m]
DefineConstant[ fine = 0.02 ];      // element size on the contacts [m]
DefineConstant[ bar_h = 0.16 ];     // bar height [m] (the design variant: 0.174)

SetFactory("OpenCASCADE");
half_length = 3.67 / 2;  half_width = 0.24;  height = 0.48;
slot_h = 0.176;                      // slot height [m]
bar_w = 0.08;                        // half width of the bar [m]
thin = 0.015;  thick = 0.025;        // side cast iron at the V's ends and apex [m]
x0 = 0.1;                            // half the middle section without bar [m]
bar_end = x0 + 2.175;                // the bar's end [m]
e = 1e-6;

// The slot's cross-section (y, z) at x = 0, extruded along the block.
Point(1) = {0, 0, 0};
Point(2) = {0, bar_w + thin, 0};
Point(3) = {0, bar_w + thick, slot_h / 2};
Point(4) = {0, bar_w + thin, slot_h};
Point(5) = {0, 0, slot_h};
For i In {1 : 5}
  Line(i) = {i, i % 5 + 1};
EndFor
Curve Loop(1) = {1, 2, 3, 4, 5};
Plane Surface(1) = {1};
slot[] = Extrude {half_length, 0, 0} { Surface{1}; };
// The cast iron fills the slot from x0 to the block's end; the bar runs out of it.
base[] = Translate {x0, 0, 0} { Duplicata { Surface{1}; } };
cast[] = Extrude {half_length - x0, 0, 0} { Surface{base[0]}; };
box = newv;
Box(box) = {0, 0, 0, half_length, half_width, height};
block[] = BooleanDifference{ Volume{box}; Delete; }{ Volume{slot[1]}; Delete; };
rod = newv;
Box(rod) = {x0, 0, 0, bar_end - x0, bar_w, bar_h};
BooleanFragments{ Volume{block[]}; Delete; }{ Volume{cast[1], rod}; Delete; }

bar[] = Volume In BoundingBox{x0 - e, -e, -e, bar_end + e, bar_w + e, bar_h + e};
slot_fill[] = Volume In BoundingBox{x0 - e, -e, -e, half_length + e, bar_w + thick + e, slot_h + e};
iron[] = slot_fill[];
iron[] -= bar[];
all[] = Volume{:};
carbon[] = all[];
carbon[] -= slot_fill[];
carbon[] -= bar[];
Physical Volume("block") = carbon[];
Physical Volume("cast_iron") = iron[];
Physical Volume("bar") = bar[];

side[] = Surface In BoundingBox{x0 - e, bar_w + thin - e, -e, half_length + e, bar_w + thick + e, slot_h + e};
Physical Surface("slot_side") = side[];
Physical Surface("slot_top") = Surface In BoundingBox{x0 - e, -e, slot_h - e, half_length + e, bar_w + thin + e, slot_h + e};
Physical Surface("bar_side") = Surface In BoundingBox{x0 - e, bar_w - e, -e, half_length + e, bar_w + e, bar_h + e};
Physical Surface("bar_top") = Surface In BoundingBox{x0 - e, -e, bar_h - e, half_length + e, bar_w + e, bar_h + e};
Physical Surface("top") = Surface In BoundingBox{-e, -e, height - e, half_length + e, half_width + e, height + e};
ends[] = Surface In BoundingBox{half_length - e, -e, -e, half_length + e, half_width + e, height + e};
ends[] -= Surface In BoundingBox{half_length - e, -e, -e, half_length + e, bar_w + e, bar_h + e};
Physical Surface("block_end") = ends[];
Physical Surface("block_side") = Surface In BoundingBox{-e, half_width - e, -e, half_length + e, half_width + e, height + e};
Physical Surface("bottom") = Surface In BoundingBox{-e, -e, -e, half_length + e, half_width + e, e};
Physical Surface("symmetry_x") = Surface In BoundingBox{-e, -e, -e, e, half_width + e, height + e};
Physical Surface("symmetry_y") = Surface In BoundingBox{-e, -e, -e, bar_end + e, e, height + e};
outside[] = Surface In BoundingBox{half_length - e, -e, -e, bar_end + e, bar_w + e, bar_h + e};
outside[] -= Surface In BoundingBox{half_length - e, -e, -e, half_length + e, bar_w + e, bar_h + e};
outside[] -= Surface In BoundingBox{bar_end - e, -e, -e, bar_end + e, bar_w + e, bar_h + e};
outside[] -= Surface In BoundingBox{half_length - e, -e, -e, bar_end + e, e, bar_h + e};
Physical Surface("bar_surface") = outside[];
Physical Surface("bar_end") = Surface In BoundingBox{bar_end - e, -e, -e, bar_end + e, bar_w + e, bar_h + e};

MeshSize{ PointsOf{ Volume{:}; } } = size;
MeshSize{ PointsOf{ Volume{iron[]}; } } = fine;
