"""PixArt PMW3901MB optical-flow chip on SPI: register map, RTL core, TLM model, PX4 driver."""
