"""Missions: the items (MAVLink's mission items, the same for a scenario file and a ground
station), the geofence's geometry, and the executor that turns a plan into the controller's
full-pose reference as the vehicle flies it."""
