// Reads one OpenIGTLink IMAGE message (header + body) from stdin, unpacks it with the
// OpenIGTLink C++ library (CRC checked) and prints the geometry the library sees, one
// "key: values" line each. Test helper for tests/protocol/test_interop_cpp.py.
#include <iostream>
#include <iterator>
#include <string>
#include <vector>
#include <cstring>

#include "igtlImageMessage.h"
#include "igtlMessageHeader.h"

int main()
{
  std::vector<char> data((std::istreambuf_iterator<char>(std::cin)),
                         std::istreambuf_iterator<char>());
  igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
  header->InitPack();
  if (data.size() < (size_t)header->GetPackSize())
    {
    std::cout << "error: short header" << std::endl;
    return 1;
    }
  std::memcpy(header->GetPackPointer(), &data[0], header->GetPackSize());
  header->Unpack();
  igtl::ImageMessage::Pointer image = igtl::ImageMessage::New();
  image->SetMessageHeader(header);
  image->AllocatePack();
  if (data.size() != (size_t)(header->GetPackSize() + image->GetPackBodySize()))
    {
    std::cout << "error: body size" << std::endl;
    return 1;
    }
  std::memcpy(image->GetPackBodyPointer(), &data[header->GetPackSize()],
              image->GetPackBodySize());
  int status = image->Unpack(1);
  std::cout << "crc_ok: " << ((status & igtl::MessageHeader::UNPACK_BODY) ? 1 : 0) << std::endl;
  int size[3];
  float spacing[3], origin[3], t[3], s[3], n[3];
  image->GetDimensions(size);
  image->GetSpacing(spacing);
  image->GetOrigin(origin);
  image->GetNormals(t, s, n);
  std::cout.precision(9);
  std::cout << "size: " << size[0] << " " << size[1] << " " << size[2] << std::endl;
  std::cout << "spacing: " << spacing[0] << " " << spacing[1] << " " << spacing[2] << std::endl;
  std::cout << "origin: " << origin[0] << " " << origin[1] << " " << origin[2] << std::endl;
  std::cout << "t: " << t[0] << " " << t[1] << " " << t[2] << std::endl;
  std::cout << "s: " << s[0] << " " << s[1] << " " << s[2] << std::endl;
  std::cout << "n: " << n[0] << " " << n[1] << " " << n[2] << std::endl;
  std::cout << "scalar_type: " << image->GetScalarType() << std::endl;
  std::cout << "components: " << image->GetNumComponents() << std::endl;
  std::cout << "endian: " << image->GetEndian() << std::endl;
  std::cout << "coordinate: " << image->GetCoordinateSystem() << std::endl;
  const unsigned char* pixels = (const unsigned char*)image->GetScalarPointer();
  long nbytes = image->GetImageSize();
  unsigned long sum = 0;
  for (long i = 0; i < nbytes; i++)
    {
    sum = sum * 31 + pixels[i];
    }
  std::cout << "pixel_bytes: " << nbytes << std::endl;
  std::cout << "pixel_hash: " << sum << std::endl;
  return 0;
}
