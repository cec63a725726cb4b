// Reads one OpenIGTLink POLYDATA message (header + body, header v1) from stdin and unpacks
// it with the OpenIGTLink 3 C++ library (CRC checked), as 3D Slicer's connector does before
// OpenIGTLinkIO's converter sees it; writes what the library read, one item a line:
//   points N / p x y z (N lines)
//   cells <section> NCELLS / c k id... (one line a cell), for vertices lines polygons strips
//   attributes N / a <name> <TYPE> <NCOMPONENTS> <N> / d v... (one line a row)
// Built with -DIGTLIO_CONVERTER, it then hands the message to OpenIGTLinkIO's converter
// (igtlioPolyDataConverter::IGTLToVTKPolyData, what makes Slicer's model) and writes the
// vtkPolyData it made: vtkverts <legacy cell array...> / vtkarray <name> <ncomp> / r v...
// Test helper for tests/bridge/test_polydata_readers.py.
#include <cstdio>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

#include "igtlMessageHeader.h"
#include "igtlPolyDataMessage.h"

#ifdef IGTLIO_CONVERTER
#include <vtkCellArray.h>
#include <vtkDataArray.h>
#include <vtkIdTypeArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>

#include "igtlioPolyDataConverter.h"

static void converted(igtl::PolyDataMessage::Pointer msg)
{
  vtkSmartPointer<vtkPolyData> poly = vtkSmartPointer<vtkPolyData>::New();
  if (!igtlioPolyDataConverter::IGTLToVTKPolyData(msg, poly))
    {
    std::printf("vtkfailed\n");
    return;
    }
  vtkNew<vtkIdTypeArray> legacy;
  poly->GetVerts()->ExportLegacyFormat(legacy);
  std::printf("vtkverts");
  for (vtkIdType i = 0; i < legacy->GetNumberOfValues(); i++)
    {
    std::printf(" %lld", static_cast<long long>(legacy->GetValue(i)));
    }
  std::printf("\n");
  vtkPointData* data = poly->GetPointData();
  for (int a = 0; a < data->GetNumberOfArrays(); a++)
    {
    vtkDataArray* array = data->GetArray(a);
    const int ncomp = array->GetNumberOfComponents();
    std::printf("vtkarray %s %d\n", array->GetName(), ncomp);
    for (vtkIdType t = 0; t < array->GetNumberOfTuples(); t++)
      {
      std::printf("r");
      for (int k = 0; k < ncomp; k++)
        {
        std::printf(" %.9g", array->GetComponent(t, k));
        }
      std::printf("\n");
      }
    }
}
#endif

static void cells(const char* section, igtl::PolyDataCellArray* array)
{
  const unsigned int n = array ? array->GetNumberOfCells() : 0;
  std::printf("cells %s %u\n", section, n);
  for (unsigned int i = 0; i < n; i++)
    {
    std::vector<igtlUint32> ids(array->GetCellSize(i));
    if (!ids.empty())
      {
      array->GetCell(i, ids.data());
      }
    std::printf("c %zu", ids.size());
    for (size_t j = 0; j < ids.size(); j++)
      {
      std::printf(" %u", ids[j]);
      }
    std::printf("\n");
    }
}

int main()
{
  std::string raw((std::istreambuf_iterator<char>(std::cin)), std::istreambuf_iterator<char>());
  igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
  header->InitPack();
  if (raw.size() < static_cast<size_t>(header->GetPackSize()))
    {
    std::fprintf(stderr, "short input: %zu bytes\n", raw.size());
    return 2;
    }
  raw.copy(static_cast<char*>(header->GetPackPointer()), header->GetPackSize());
  header->Unpack();
  igtl::PolyDataMessage::Pointer msg = igtl::PolyDataMessage::New();
  msg->SetMessageHeader(header);
  msg->AllocatePack();
  if (raw.size() != static_cast<size_t>(header->GetPackSize() + msg->GetPackBodySize()))
    {
    std::fprintf(stderr, "body of %zu bytes, header says %lu\n",
                 raw.size() - header->GetPackSize(),
                 static_cast<unsigned long>(msg->GetPackBodySize()));
    return 2;
    }
  raw.copy(static_cast<char*>(msg->GetPackBodyPointer()), msg->GetPackBodySize(),
           header->GetPackSize());
  if (!(msg->Unpack(1) & igtl::MessageHeader::UNPACK_BODY))
    {
    std::fprintf(stderr, "Unpack refused the body (CRC or content)\n");
    return 3;
    }
  igtl::PolyDataPointArray::Pointer points = msg->GetPoints();
  const unsigned int npoints = points.IsNotNull() ? points->GetNumberOfPoints() : 0;
  std::printf("points %u\n", npoints);
  for (unsigned int i = 0; i < npoints; i++)
    {
    igtlFloat32 p[3];
    points->GetPoint(i, p);
    std::printf("p %.9g %.9g %.9g\n", p[0], p[1], p[2]);
    }
  cells("vertices", msg->GetVertices());
  cells("lines", msg->GetLines());
  cells("polygons", msg->GetPolygons());
  cells("strips", msg->GetTriangleStrips());
  const unsigned int nattributes = msg->GetNumberOfAttributes();
  std::printf("attributes %u\n", nattributes);
  for (unsigned int i = 0; i < nattributes; i++)
    {
    igtl::PolyDataAttribute* attr = msg->GetAttribute(igtl::PolyDataMessage::AttributeList::size_type(i));
    const unsigned int ncomp = attr->GetNumberOfComponents();
    const unsigned int rows = attr->GetSize();
    std::printf("a %s %d %u %u\n", attr->GetName(), attr->GetType(), ncomp, rows);
    std::vector<igtlFloat32> row(ncomp);
    for (unsigned int r = 0; r < rows; r++)
      {
      attr->GetNthData(r, row.data());
      std::printf("d");
      for (unsigned int k = 0; k < ncomp; k++)
        {
        std::printf(" %.9g", row[k]);
        }
      std::printf("\n");
      }
    }
#ifdef IGTLIO_CONVERTER
  std::fflush(stdout);  // what the library read is out, should the converter crash
  converted(msg);
#endif
  return 0;
}
