// A gtest (ament_add_gtest) that fails without a ROS_DOMAIN_ID of its own.
#include <cstdlib>
#include <string>

#include <gtest/gtest.h>

TEST(DomainGtest, HasADomainId)
{
  const char * value = std::getenv("ROS_DOMAIN_ID");
  ASSERT_NE(value, nullptr);
  EXPECT_FALSE(std::string(value).empty());
}
