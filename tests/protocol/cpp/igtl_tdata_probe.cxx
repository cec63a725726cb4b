// TDATA both ways with the OpenIGTLink 3 C++ library 3D Slicer links.
//   "pack":   writes to stdout one TDATA message (header + body) of two elements packed by
//             the library: "tool" (6D, a translation (1, 2, 3) mm, R12 = 0.5) and "ref"
//             (tracker, identity).
//   "unpack": reads one TDATA message from stdin, checks its CRC, and prints per element
//             "name type m00 m01 ... m23" (the upper 3 rows, as the library unpacks them).
// Test helper for tests/protocol/test_interop_igtl3.py.
#include <cstdio>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

#include "igtlMessageHeader.h"
#include "igtlTrackingDataMessage.h"

static int pack()
{
  igtl::TrackingDataMessage::Pointer msg = igtl::TrackingDataMessage::New();
  msg->SetDeviceName("poses:demo");
  igtl::TrackingDataElement::Pointer tool = igtl::TrackingDataElement::New();
  tool->SetName("tool");
  tool->SetType(igtl::TrackingDataElement::TYPE_6D);
  igtl::Matrix4x4 m;
  igtl::IdentityMatrix(m);
  m[0][3] = 1; m[1][3] = 2; m[2][3] = 3; m[0][1] = 0.5f;
  tool->SetMatrix(m);
  msg->AddTrackingDataElement(tool);
  igtl::TrackingDataElement::Pointer ref = igtl::TrackingDataElement::New();
  ref->SetName("ref");
  ref->SetType(igtl::TrackingDataElement::TYPE_TRACKER);
  igtl::IdentityMatrix(m);
  ref->SetMatrix(m);
  msg->AddTrackingDataElement(ref);
  msg->Pack();
  std::cout.write(static_cast<const char*>(msg->GetPackPointer()), msg->GetPackSize());
  return std::cout.good() ? 0 : 1;
}

static int unpack()
{
  std::vector<char> raw((std::istreambuf_iterator<char>(std::cin)),
                        std::istreambuf_iterator<char>());
  igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
  header->InitPack();
  if (raw.size() < static_cast<size_t>(header->GetPackSize()))
    {
    return 2;
    }
  std::copy(raw.begin(), raw.begin() + header->GetPackSize(),
            static_cast<char*>(header->GetPackPointer()));
  header->Unpack();
  igtl::TrackingDataMessage::Pointer msg = igtl::TrackingDataMessage::New();
  msg->SetMessageHeader(header);
  msg->AllocatePack();
  if (raw.size() != static_cast<size_t>(header->GetPackSize() + msg->GetPackBodySize()))
    {
    return 3;
    }
  std::copy(raw.begin() + header->GetPackSize(), raw.end(),
            static_cast<char*>(msg->GetPackBodyPointer()));
  if (!(msg->Unpack(1) & igtl::MessageHeader::UNPACK_BODY))
    {
    return 4;  // CRC or size refused
    }
  for (int i = 0; i < msg->GetNumberOfTrackingDataElements(); i++)
    {
    igtl::TrackingDataElement::Pointer element;
    msg->GetTrackingDataElement(i, element);
    igtl::Matrix4x4 m;
    element->GetMatrix(m);
    std::printf("%s %d", element->GetName(), element->GetType());
    for (int r = 0; r < 3; r++)
      for (int c = 0; c < 4; c++)
        std::printf(" %.6g", m[r][c]);
    std::printf("\n");
    }
  return 0;
}

int main(int argc, char** argv)
{
  const std::string mode = argc > 1 ? argv[1] : "";
  return mode == "pack" ? pack() : mode == "unpack" ? unpack() : 1;
}
