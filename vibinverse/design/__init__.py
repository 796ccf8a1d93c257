"""Design of observation: which view, time of day, footprint, polarizer, frame rate and duration
make a vibration detectable and its parameters sharp (`vibinverse design`)."""
