// A gmock test (ament_add_gmock) that fails without a ROS_DOMAIN_ID of its own.
#include <cstdlib>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

class Environment
{
public:
  virtual ~Environment() = default;
  virtual std::string get(const std::string & name) const = 0;
};

class MockEnvironment : public Environment
{
public:
  MOCK_METHOD(std::string, get, (const std::string & name), (const, override));
};

std::string domain_of(const Environment & environment)
{
  return environment.get("ROS_DOMAIN_ID");
}

TEST(DomainGmock, HasADomainId)
{
  const char * value = std::getenv("ROS_DOMAIN_ID");
  ASSERT_NE(value, nullptr);
  MockEnvironment environment;
  EXPECT_CALL(environment, get("ROS_DOMAIN_ID")).WillOnce(::testing::Return(value));
  EXPECT_EQ(domain_of(environment), std::string(value));
}
