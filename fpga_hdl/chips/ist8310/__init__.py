"""iSentek IST8310 3-axis magnetometer on I2C: register map, RTL core, TLM model, PX4 driver."""
