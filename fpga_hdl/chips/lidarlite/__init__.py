"""Garmin LIDAR-Lite v3 rangefinder on I2C: register map, RTL core, TLM model, PX4 driver."""
