from wmrid.cli.app import main

main()
