// A gtest that writes down the ROS_DOMAIN_ID it ran on, as the token talkers do
// ($CROSSTALK_RECORD_DIR/gtest.json when that variable is set).
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

TEST(RecordDomain, WritesDownItsDomain)
{
  const char * record_dir = std::getenv("CROSSTALK_RECORD_DIR");
  if (record_dir == nullptr) {
    return;
  }
  const char * domain_id = std::getenv("ROS_DOMAIN_ID");
  const double now = std::chrono::duration<double>(
    std::chrono::system_clock::now().time_since_epoch()).count();
  std::ofstream record(std::string(record_dir) + "/gtest.json");
  record << std::fixed << "{\"token\": \"gtest\", \"domain_id\": "
         << (domain_id ? "\"" + std::string(domain_id) + "\"" : std::string("null"))
         << ", \"pid\": " << getpid() << ", \"start\": " << now << ", \"end\": " << now
         << ", \"own_received\": 0, \"foreign\": {}, \"passed\": true}\n";
  ASSERT_TRUE(record.good());
}
