// jAER AEDAT 2.0 reader (DVS128 address layout): ASCII header lines starting with '#' (the
// first is "#!AER-DAT2.0"), then big-endian pairs of int32 address + int32 timestamp (us).
// DVS128 address: bit 0 polarity (1 = ON), bits 1-7 127 - x, bits 8-14 y (jAER, origin bottom
// left), bit 15 external event. evio reports image coordinates with origin top left:
// x = 127 - bits(1-7), y = 127 - bits(8-14). External events go to read_triggers().
#pragma once

#include <memory>
#include <string>

#include "evio/sensors/dataset.h"

namespace evio {

std::unique_ptr<DatasetReader> open_aedat2_dataset(const std::string& path, const DatasetOptions& options = {});

}  // namespace evio
