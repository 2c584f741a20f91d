"""An rclpy token exchange for tests that must fail when another test shares their domain."""
