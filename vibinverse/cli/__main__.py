from vibinverse.cli import entry

entry()
