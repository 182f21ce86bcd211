// libFuzzer target: the MCAP container (header, footer, summary or linear scan, chunk
// decompression, message iteration) on arbitrary bytes; every channel's messages are read.
#include <cstdint>
#include <vector>

#include "../../sensors/src/mcap_container.h"
#include "evio/calib/error.h"
#include "fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  evio_fuzz::silence_log();
  evio_fuzz::MemFile file(data, size);
  if (!file.ok()) return 0;
  try {
    const evio::detail::mcap::File mcap(file.path());
    std::vector<uint16_t> ids;
    for (const auto& c : mcap.channels()) ids.push_back(c.id);
    evio::detail::mcap::MessageCursor cursor(mcap, ids);
    evio::detail::mcap::Message m;
    uint64_t sum = 0;
    while (cursor.next(&m)) {
      if (m.size > 0) sum += m.data[0] + m.data[m.size - 1];  // touch the payload's ends
      sum += m.channel->id;
      (void)cursor.progress();
    }
    (void)sum;
  } catch (const evio::InputError&) {
  }
  return 0;
}
