"""TE MS5611 barometer on SPI: commands and PROM, gateware, transaction-level model, driver."""
