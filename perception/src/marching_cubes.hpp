#pragma once
// Marching Cubes case table (Lorensen & Cline 1987), generated rather than transcribed: for each
// of the 256 inside/outside patterns of a cell's corners, the crossing edges are joined face by
// face into closed loops and each loop is fanned into triangles. On a face whose diagonal corners
// are inside (the ambiguous case) the inside corners are always cut off separately; the rule
// depends on the face alone, so neighbouring cells agree and the surface has no cracks.
//
// Corner c sits at (c & 1, (c >> 1) & 1, (c >> 2) & 1). Edge e runs along axis e / 4 from the
// corner whose other two coordinates are the bits of e % 4 (lower bit: the lower remaining
// axis). Triangles are counter-clockwise seen from the outside region.
#include <array>
#include <cstdint>
#include <vector>

namespace artisan::mc {

struct Case {
  std::vector<std::array<uint8_t, 3>> triangles;  ///< edge ids
};

/// The 256 cases; bit c of the index set when corner c is inside.
const std::array<Case, 256>& cases();

/// Corner offset of edge e's lower end, and its axis.
inline std::array<int, 3> edge_origin(int e) {
  const int axis = e / 4, a = (e % 4) & 1, b = (e % 4) >> 1;
  std::array<int, 3> o{0, 0, 0};
  const int u = axis == 0 ? 1 : 0, v = axis == 2 ? 1 : 2;
  o[u] = a;
  o[v] = b;
  return o;
}
inline int edge_axis(int e) { return e / 4; }

}  // namespace artisan::mc
