// CRC-32C: the standard check value, the instruction and the tables agreeing, continuation.
#include <catch2/catch.hpp>

#include <random>
#include <string_view>
#include <vector>

#include "kinema/files.hpp"

using namespace kinema;

TEST_CASE("crc32c gives the Castagnoli check value and the same with or without SSE4.2", "[files]") {
  const std::string_view check = "123456789";
  const auto bytes = std::as_bytes(std::span(check.data(), check.size()));
  CHECK(crc32c(bytes) == 0xE3069283u);
  CHECK(crc32c(bytes, 0, false) == 0xE3069283u);
  CHECK(crc32c({}) == 0);
  std::mt19937 random(7);
  std::vector<std::byte> data(1 << 20);
  for (std::byte& b : data) b = std::byte(random() & 0xFF);
  // Past 768 bytes three interleaved streams are joined: lengths around that and odd ones.
  for (std::size_t n : {1u, 7u, 8u, 9u, 63u, 64u, 65u, 767u, 768u, 769u, 791u, 4999u, 1000003u}) {
    INFO(n << " bytes");
    const std::span<const std::byte> part(data.data(), n);
    CHECK(crc32c(part) == crc32c(part, 0, false));
    // The CRC of a whole is the CRC of its tail continued from that of its head.
    CHECK(crc32c(std::span<const std::byte>(data.data(), data.size())) ==
          crc32c(std::span<const std::byte>(data.data() + n, data.size() - n), crc32c(part)));
  }
}
