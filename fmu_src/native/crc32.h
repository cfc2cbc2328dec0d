/* CRC-32 (IEEE 802.3, the one of Python's zlib.crc32) of a serialized FMU state: the
   native layer and the pythonfmu shim refuse a blob whose checksum does not match, since
   a state with one byte changed would otherwise restore silently wrong numbers. */
#ifndef MB_CRC32_H
#define MB_CRC32_H
#include <stddef.h>

static unsigned long mb_crc32(const void *bytes, size_t n)
{
    const unsigned char *p = bytes;
    unsigned long crc = 0xFFFFFFFFul;
    for (size_t i = 0; i < n; i++) {
        crc ^= p[i];
        for (int k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320ul & (0ul - (crc & 1ul)));
    }
    return crc ^ 0xFFFFFFFFul;
}
#endif
