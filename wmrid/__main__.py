from wmrid.cli import main

main()
