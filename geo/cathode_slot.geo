// A cathode block with a collector bar sealed into its slot by cast iron: three bodies, four
// flat contacts. Half of the cross-section (x >= 0, the slot's middle plane at x = 0 is a
// symmetry plane); with depth > 0, a slice of that length along the bar (z), in 3D.
// Dimensions after Dupuis, Light Metals 2011 (see ../shared/HALL-HEROULT.md): a block 48 cm
// high, a slot 200 mm wide and 176 mm high, 20 mm of cast iron on each side and 16 mm above a
// bar of 160 mm × 160 mm (the V-shaped sides of the real slot are straight here).
//
// Physical groups (names are what the Python scripts use):
//   block, cast_iron, bar            the bodies
//   slot_side, slot_top              block / cast iron contacts (x = 0.1, y = 0.176)
//   bar_side, bar_top                cast iron / bar contacts (x = 0.08, y = 0.16)
//   top                              the block's top face (the bath side)
//   block_side                       the block's outer side, x = width
//   bottom                           y = 0 under the block and the cast iron
//   bar_bottom                       y = 0 under the bar (where the current leaves, in 2D)
//   symmetry                         x = 0, every body
//   front, back                      z = 0 and z = depth, every body (3D only)
//
// Parameters (override with load_scene(..., parameters={"size": 0.01})):
DefineConstant[ width = 0.3 ];    // half width of the block [m]
DefineConstant[ height = 0.48 ];  // block height [m]
DefineConstant[ depth = 0 ];      // 0: the 2D cross-section; > 0: a 3D slice of this length [m]
DefineConstant[ size = 0.02 ];    // element size away from the slot [m]
DefineConstant[ fine = 0.008 ];   // element size on the contacts [m]

SetFactory("OpenCASCADE");
slot_w = 0.1;  slot_h = 0.176;   // half width and height of the slot
bar_w = 0.08;  bar_h = 0.16;     // half width and height of the bar
e = 1e-6;
If (depth == 0)
  Rectangle(1) = {0, 0, 0, width, height};
  Rectangle(2) = {0, 0, 0, slot_w, slot_h};
  Rectangle(3) = {0, 0, 0, bar_w, bar_h};
  BooleanFragments{ Surface{1}; Delete; }{ Surface{2, 3}; Delete; }
  bar[] = Surface In BoundingBox{-e, -e, -e, bar_w + e, bar_h + e, e};
  slot[] = Surface In BoundingBox{-e, -e, -e, slot_w + e, slot_h + e, e};
  cast[] = slot[];
  cast[] -= bar[];
  all[] = Surface{:};
  block[] = all[];
  block[] -= slot[];
  Physical Surface("block") = block[];
  Physical Surface("cast_iron") = cast[];
  Physical Surface("bar") = bar[];
  Physical Curve("slot_side") = Curve In BoundingBox{slot_w - e, -e, -e, slot_w + e, slot_h + e, e};
  Physical Curve("slot_top") = Curve In BoundingBox{-e, slot_h - e, -e, slot_w + e, slot_h + e, e};
  Physical Curve("bar_side") = Curve In BoundingBox{bar_w - e, -e, -e, bar_w + e, bar_h + e, e};
  Physical Curve("bar_top") = Curve In BoundingBox{-e, bar_h - e, -e, bar_w + e, bar_h + e, e};
  Physical Curve("top") = Curve In BoundingBox{-e, height - e, -e, width + e, height + e, e};
  Physical Curve("block_side") = Curve In BoundingBox{width - e, -e, -e, width + e, height + e, e};
  Physical Curve("bottom") = Curve In BoundingBox{bar_w - e, -e, -e, width + e, e, e};
  Physical Curve("bar_bottom") = Curve In BoundingBox{-e, -e, -e, bar_w + e, e, e};
  Physical Curve("symmetry") = Curve In BoundingBox{-e, -e, -e, e, height + e, e};
  contacts[] = Curve In BoundingBox{-e, -e, -e, slot_w + e, slot_h + e, e};
  MeshSize{ PointsOf{ Curve{contacts[]}; } } = fine;
Else
  Box(1) = {0, 0, 0, width, height, depth};
  Box(2) = {0, 0, 0, slot_w, slot_h, depth};
  Box(3) = {0, 0, 0, bar_w, bar_h, depth};
  BooleanFragments{ Volume{1}; Delete; }{ Volume{2, 3}; Delete; }
  bar[] = Volume In BoundingBox{-e, -e, -e, bar_w + e, bar_h + e, depth + e};
  slot[] = Volume In BoundingBox{-e, -e, -e, slot_w + e, slot_h + e, depth + e};
  cast[] = slot[];
  cast[] -= bar[];
  all[] = Volume{:};
  block[] = all[];
  block[] -= slot[];
  Physical Volume("block") = block[];
  Physical Volume("cast_iron") = cast[];
  Physical Volume("bar") = bar[];
  Physical Surface("slot_side") = Surface In BoundingBox{slot_w - e, -e, -e, slot_w + e, slot_h + e, depth + e};
  Physical Surface("slot_top") = Surface In BoundingBox{-e, slot_h - e, -e, slot_w + e, slot_h + e, depth + e};
  Physical Surface("bar_side") = Surface In BoundingBox{bar_w - e, -e, -e, bar_w + e, bar_h + e, depth + e};
  Physical Surface("bar_top") = Surface In BoundingBox{-e, bar_h - e, -e, bar_w + e, bar_h + e, depth + e};
  Physical Surface("top") = Surface In BoundingBox{-e, height - e, -e, width + e, height + e, depth + e};
  Physical Surface("block_side") = Surface In BoundingBox{width - e, -e, -e, width + e, height + e, depth + e};
  Physical Surface("bottom") = Surface In BoundingBox{bar_w - e, -e, -e, width + e, e, depth + e};
  Physical Surface("bar_bottom") = Surface In BoundingBox{-e, -e, -e, bar_w + e, e, depth + e};
  Physical Surface("symmetry") = Surface In BoundingBox{-e, -e, -e, e, height + e, depth + e};
  Physical Surface("front") = Surface In BoundingBox{-e, -e, -e, width + e, height + e, e};
  Physical Surface("back") = Surface In BoundingBox{-e, -e, depth - e, width + e, height + e, depth + e};
  contacts[] = Surface In BoundingBox{-e, -e, -e, slot_w + e, slot_h + e, depth + e};
  MeshSize{ PointsOf{ Surface{contacts[]}; } } = fine;
EndIf
Mesh.MeshSizeMax = size;
