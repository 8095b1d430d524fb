"""InvenSense MPU-6000 IMU on SPI: register map, gateware, transaction-level model, driver."""
