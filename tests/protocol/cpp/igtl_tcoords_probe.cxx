// Writes to stdout one OpenIGTLink POLYDATA message (header + body) packed by the
// OpenIGTLink 3 C++ library: a 10 mm cube (8 points, 6 quads) with texture coordinates,
// point data ("point", TYPE 0x05) or cell data ("cell", TYPE 0x15). The attribute is
// filled the way OpenIGTLinkIO's igtlioPolyDataConverter::VTKToIGTLAttribute fills it
// for a vtkCubeSource's TCoords (SetType(POINT_TCOORDS | cell bit), SetSize, SetNthData
// from a 9-float tuple of which VTK sets 2); the tuple is zeroed here so the bytes are
// the same every run. Test helper for tests/protocol/test_interop_cpp.py.
#include <iostream>
#include <string>

#include "igtlPolyDataMessage.h"

int main(int argc, char** argv)
{
  const bool cell = argc > 1 && std::string(argv[1]) == "cell";
  igtl::PolyDataMessage::Pointer msg = igtl::PolyDataMessage::New();
  msg->SetDeviceName("Cube");
  igtl::PolyDataPointArray::Pointer points = igtl::PolyDataPointArray::New();
  igtlFloat32 corners[8][3] = {{-5, -5, -5}, {5, -5, -5}, {-5, 5, -5}, {5, 5, -5},
                               {-5, -5, 5},  {5, -5, 5},  {-5, 5, 5},  {5, 5, 5}};
  for (int i = 0; i < 8; i++)
    {
    points->AddPoint(corners[i]);
    }
  msg->SetPoints(points);
  igtl::PolyDataCellArray::Pointer polygons = igtl::PolyDataCellArray::New();
  igtlUint32 quads[6][4] = {{0, 1, 3, 2}, {4, 5, 7, 6}, {0, 1, 5, 4},
                            {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 3, 7, 5}};
  for (int i = 0; i < 6; i++)
    {
    polygons->AddCell(4, quads[i]);
    }
  msg->SetPolygons(polygons);
  igtl::PolyDataAttribute::Pointer tcoords = igtl::PolyDataAttribute::New();
  tcoords->SetType(cell ? igtl::PolyDataAttribute::CELL_TCOORDS
                        : igtl::PolyDataAttribute::POINT_TCOORDS);
  const int n = cell ? 6 : 8;
  tcoords->SetSize(n);
  tcoords->SetName("TCoords");
  for (int j = 0; j < n; j++)
    {
    igtlFloat32 tuple[9] = {0};
    tuple[0] = 0.25f * j;
    tuple[1] = 0.5f;
    tcoords->SetNthData(j, tuple);
    }
  msg->AddAttribute(tcoords);
  msg->Pack();
  std::cout.write(static_cast<const char*>(msg->GetPackPointer()), msg->GetPackSize());
  return std::cout.good() ? 0 : 1;
}
